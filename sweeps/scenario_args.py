"""``coman-sweep`` scenario options: ``--axis NAME=V1,V2,...`` and one-valued flags, for ``--model mjx``.

    coman-sweep map --model mjx --axis payload_kg=0,1 --axis slope_deg=0,5 --terrain rough:2
    coman-sweep compare --model mjx --axis terrain=flat,stairs:5 --delay-ms 10

Axes (:data:`sweeps.grid.SCENARIO_AXES`, fields of
:class:`mjx_coman.scenarios.Scenario`): ``payload_kg``, ``slope_deg``,
``imu_noise_deg``, ``joint_noise_deg``, ``delay_ms`` (batched: one
compilation runs every combination with the push grid) and ``terrain``
(``flat``, ``rough:CM[:SEED]``, ``stairs:CM``: a scene each, so each
terrain is its own run, in ``OUT/terrain-<value>``, and compilation). A flag
such as ``--payload-kg 1`` is an axis of one value. The scenario is part of
the sweep's configuration and its hash: resuming never mixes scenarios.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from sweeps.grid import SCENARIO_AXES, GridError, freeze_scenario

FLAGS = {a: "--" + a.replace("_", "-") for a in SCENARIO_AXES}
_HELP = {
    "payload_kg": "mass added to the torso, kg (seed 001: 1)",
    "slope_deg": "floor slope, + uphill in the walking direction, deg",
    "imu_noise_deg": "std of the IMU orientation noise, deg (seed 001: 3)",
    "joint_noise_deg": "std of the link encoder noise, deg (seed 001: 1)",
    "delay_ms": "extra controller-to-robot delay on the plant's 20 ms, ms (seed 001: 10)",
    "terrain": "flat, rough:CM[:SEED] (+-CM cm height field) or stairs:CM (risers, up in +x)",
    "actuator": "ideal or sea: how a torque plant realises torque commands (position plants ignore it)",
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``--axis`` and one flag per axis (values parsed later, by :func:`scenario_axes`)."""
    g = p.add_argument_group("scenario (mjx: mjx_coman.scenarios; the controllers are not told)")
    g.add_argument("--axis", action="append", default=None, metavar="NAME=V1,V2,...",
                   help=f"a scenario axis (repeatable): {', '.join(SCENARIO_AXES)}")
    for a, flag in FLAGS.items():
        g.add_argument(flag, dest=f"scenario_{a}", default=None, metavar="V", help=_HELP[a] + " (one value)")


def given(args) -> bool:
    """Whether any scenario option was given."""
    return bool(getattr(args, "axis", None)) or any(getattr(args, f"scenario_{a}", None) is not None
                                                     for a in SCENARIO_AXES)


def _values(name: str, text: str, where: str) -> tuple:
    vals = [v.strip() for v in str(text).split(",") if v.strip()]
    if not vals:
        raise GridError(f"{where} gives no values for {name}")
    if name == "terrain":
        from mjx_coman.scenarios import parse_terrain

        try:
            return tuple(parse_terrain(v).text for v in vals)
        except ValueError as e:
            raise GridError(f"{where}: {e}") from None
    if name == "actuator":
        from mjx_coman.actuators import TORQUE_LOOPS

        bad = [v for v in vals if v not in TORQUE_LOOPS]
        if bad:
            raise GridError(f"{where}: actuator {bad[0]!r} is not one of {', '.join(TORQUE_LOOPS)}")
        return tuple(vals)
    out = []
    for v in vals:
        try:
            out.append(float(v))
        except ValueError:
            raise GridError(f"{where}: {name} value {v!r} is not a number") from None
    return tuple(out)


def scenario_axes(args) -> dict:
    """``{axis: values}`` of the options (``GridError`` naming a bad name or value, or an axis given twice)."""
    out: dict = {}
    for item in getattr(args, "axis", None) or ():
        name, sep, text = str(item).partition("=")
        name = name.strip()
        if not sep:
            raise GridError(f"--axis must be NAME=V1,V2,..., got {item!r}")
        if name not in SCENARIO_AXES:
            raise GridError(f"--axis: unknown scenario axis {name!r}; choose from {', '.join(SCENARIO_AXES)}")
        if name in out:
            raise GridError(f"--axis {name} is given twice")
        out[name] = _values(name, text, f"--axis {name}")
    for a, flag in FLAGS.items():
        v = getattr(args, f"scenario_{a}", None)
        if v is None:
            continue
        if a in out:
            raise GridError(f"{flag} and --axis {a} both give {a}")
        vals = _values(a, v, flag)
        if len(vals) != 1:
            raise GridError(f"{flag} takes one value (use --axis {a}=V1,V2 for several), got {v!r}")
        out[a] = vals
    return out


def variants(args) -> list[tuple[str, tuple]]:
    """``(subfolder, scenario)`` per run: one per terrain value (``""`` and the only scenario without a
    terrain axis of several values); ``[("", ())]`` without scenario options."""
    axes = scenario_axes(args)
    terrains = axes.pop("terrain", None)
    if not terrains or len(terrains) == 1:
        if terrains:
            axes["terrain"] = terrains
        return [("", freeze_scenario(axes))]
    return [(f"terrain-{t.replace(':', '-')}", freeze_scenario(dict(axes, terrain=(t,)))) for t in terrains]


def compare_groups(plans: list) -> dict[Path, list[int]]:
    """Plan indices by folder of their comparison (one per terrain variant: the runs' parent folder)."""
    groups: dict[Path, list[int]] = {}
    for i, plan in enumerate(plans):
        groups.setdefault(Path(plan[0]).parent, []).append(i)
    return groups


def describe(summary: dict) -> str:
    """One line per scenario of a summary: its values, recovery rate and largest recovered impulse per phase
    ("" without scenario axes)."""
    from sweeps.report import percent

    lines = []
    for r in summary.get("per_scenario") or ():
        vals = ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in r["scenario"].items())
        best = ", ".join(f"{p['phase']:.2f}: " + ("-" if p["max_recovered_impulse_ns"] is None
                                                  else f"{p['max_recovered_impulse_ns']:g}") for p in r["per_phase"])
        lines.append(f"  scenario {r['scenario_index']} ({vals}): {percent(r['recovery_rate'])} recovered, "
                     f"{r['fell']} fell, {r.get('solve_failed', 0)} failed solves, {r['nan']} NaN; largest recovered impulse (N s) per phase: {best}")
    return "\n".join(lines)
