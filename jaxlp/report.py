"""The 3LP report of a robot, as a dict (JSON) or a readable table."""

from __future__ import annotations

import numpy as np

from jaxlp import control, gait as gait_mod, projection
from jaxlp.control import ERROR_NAMES
from jaxlp.presets import get_params


def _pairs(values) -> list[list[float]]:
    vals = sorted(np.asarray(values), key=lambda z: (-abs(z), -z.real, -z.imag))
    return [[float(z.real), float(z.imag)] for z in vals]


def info_report(robot: str = "coman", step_time_s: float = 0.4, speed_mps: float = 0.1,
                step_width_m: float | None = None, phases=tuple(0.1 * i for i in range(10)),
                height_m: float = 1.75, mass_kg: float = 70.0) -> dict:
    """Parameters, error-map eigenvalues, the fixed-width gait and the footstep gains.

    Raises:
        ValueError: bad robot, step time, speed or width.
    """
    params = get_params(robot, height_m=height_m, mass_kg=mass_kg)
    width = 2.0 * float(params.pw) if step_width_m is None else step_width_m
    g = gait_mod.periodic_gait(params, step_time_s, speed_mps, width)
    weights = control.default_weights(params)
    ctrl = control.constrained_dlqr(params, step_time_s, weights)
    ev_open = np.linalg.eigvals(np.asarray(ctrl.emap.A))
    ev_closed = np.linalg.eigvals(np.asarray(control.closed_loop_map(ctrl)))
    gains = {name: [] for name in ERROR_NAMES}
    for ph in phases:
        row = np.asarray(projection.footstep_gain(params, ctrl, ph * step_time_s, step_time_s))
        for name, val in zip(ERROR_NAMES, row):
            gains[name].append(float(val))
    p = params.as_dict()
    return {
        "robot": robot,
        "step_time_s": step_time_s,
        "speed_mps": speed_mps,
        "params": {k: p[k] for k in ("m1", "m2", "h1", "h2", "h3", "I2", "pw")},
        "conventions": {"exchange": "authors", "cost": weights.form,
                        "cost_mass_kg": float(params.total_mass_kg)},
        "eigenvalues_open_loop": _pairs(ev_open),
        "eigenvalues_closed_loop": _pairs(ev_closed),
        "gait": {
            "step_width_m": float(g.step_width_m),
            "pelvis_velocity_start_mps": [float(g.q0[0, 4]), float(g.q0[1, 4])],
            "hip_torque_const_nm": [float(g.u[0, 0]), float(g.u[1, 0])],
            "hip_torque_rate_nms": [float(g.u[0, 1]), float(g.u[1, 1])],
            "lateral_excursion_m": float(gait_mod.lateral_excursion_m(params, g)),
        },
        "footstep_gains": {"phase": [float(x) for x in phases], **gains},
    }


def format_table(report: dict) -> str:
    """The report as aligned text."""
    lines = [f"3LP report: robot {report['robot']}, step time {report['step_time_s']} s, "
             f"speed {report['speed_mps']} m/s", "", "parameters"]
    units = {"m1": "kg", "m2": "kg", "h1": "m", "h2": "m", "h3": "m", "I2": "kg m^2", "pw": "m"}
    for k, v in report["params"].items():
        lines.append(f"  {k:<4} {v:12.6g} {units[k]}")
    c = report["conventions"]
    lines.append(f"\nconventions: foot exchange {c['exchange']!r}, DLQR cost {c['cost']!r} "
                 f"(torque by 1/(M g)^2, M = {c['cost_mass_kg']:g} kg)")
    for key in ("eigenvalues_open_loop", "eigenvalues_closed_loop"):
        lines.append(f"\n{key.replace('_', ' ')} (sagittal step-to-step error map)")
        for re, im in report[key]:
            lines.append(f"  {re:+.6f} {im:+.6f}j   |{abs(complex(re, im)):.6f}|")
    g = report["gait"]
    lines += ["", f"gait (step width {g['step_width_m']:.4f} m, ankle torque 0)        sagittal      lateral",
              f"  pelvis velocity at phase start (m/s)   {g['pelvis_velocity_start_mps'][0]:+12.6f} {g['pelvis_velocity_start_mps'][1]:+12.6f}",
              f"  hip torque constant (N m)              {g['hip_torque_const_nm'][0]:+12.6f} {g['hip_torque_const_nm'][1]:+12.6f}",
              f"  hip torque rate (N m/s)                {g['hip_torque_rate_nms'][0]:+12.6f} {g['hip_torque_rate_nms'][1]:+12.6f}",
              f"  lateral pelvis excursion (m)           {g['lateral_excursion_m']:12.6f}"]
    fg = report["footstep_gains"]
    lines += ["", "footstep gains (final swing foot rel. pelvis, per unit error)",
              "  phase  " + "".join(f"{n:>17}" for n in ERROR_NAMES)]
    for i, ph in enumerate(fg["phase"]):
        lines.append(f"  {ph:5.2f}  " + "".join(f"{fg[n][i]:17.5f}" for n in ERROR_NAMES))
    return "\n".join(lines)
