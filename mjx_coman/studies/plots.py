"""The figure of each seed 001 and seed 004 experiment (matplotlib): ``draw(result, rows, ax_or_path)``."""

from __future__ import annotations

import math

import numpy as np


def _speeds(result, rows, axes):
    a, b = axes
    for r in sorted(rows, key=lambda r: r["label"]["speed_mps"]):
        s = r["series"]
        a.plot(s["time_s"], s["com_vel_mps"][:, 0], lw=0.7, label=f"{r['label']['speed_mps']:+.1f}")
    a.set(xlabel="time (s)", ylabel="CoM forward velocity (m/s)", title="CoM speed (Fig. 3)")
    a.legend(fontsize=6, title="command", title_fontsize=6)
    for r in rows:
        s = r["series"]
        keep = s["time_s"] >= (s["time_s"][-1] - 4.0 if len(s["time_s"]) else 0)
        b.plot(s["com_vel_mps"][keep, 1], s["com_vel_mps"][keep, 0], lw=0.6)
    b.set(xlabel="CoM lateral velocity (m/s)", ylabel="CoM forward velocity (m/s)", title="limit cycles (last 4 s)")


def _steer(result, rows, axes):
    a, b = axes
    for r in result["rows"]:
        a.scatter(r["speed_mps"], r["turn_rad_per_s"], marker="x" if r["fell"] else "o",
                  c="C3" if r["fell"] else "C2")
    a.set(xlabel="forward speed (m/s)", ylabel="steering rate (rad/s)", title="o walked, x fell (Fig. 4)")
    for r in rows:
        s = r["series"]
        b.plot(s["time_s"][: len(s["yaw_rad"]) - 1], np.diff(s["yaw_rad"]) / 0.02, lw=0.5,
               label=f"{r['label']['speed_mps']:g} m/s, {r['label']['turn_rad_per_s']:g} rad/s")
    b.set(xlabel="time (s)", ylabel="pelvis yaw rate (rad/s)")
    b.legend(fontsize=5)


def _polar_ok(result, ax, key, title):
    for r in result["rows"]:
        th = math.radians(r["direction_deg"])
        ax.scatter(th, r[key], marker="x" if r["fell"] else "o", c="C3" if r["fell"] else "C2", s=14)
    ax.set_title(title, fontsize=8)


def _push(result, rows, axes):
    a, b = axes
    _polar_ok(result, a, "impulse_ns", "impulse (N s): o recovered, x fell")
    _polar_ok({"rows": [r for r in result["rows"] if r["impulse_ns"] == 3.0]}, b, "phase",
              "3 N s at step phase (radius) (Fig. 5A)")


def _largest(result, rows, axes, key, unit):
    a, b = axes
    labels = [r["label"] for r in rows]
    xs = [next(v for k, v in lab.items() if k == key) for lab in labels]
    a.scatter(range(len(rows)), xs, c=["C3" if r["fell"] else "C2" for r in rows])
    a.set_xticks(range(len(rows)), [", ".join(f"{v}" for k, v in lab.items() if k != key) or str(x)
                                    for lab, x in zip(labels, xs)], rotation=90, fontsize=5)
    a.set(ylabel=f"{key} ({unit})", title="green walked, red fell")
    for r in rows:
        s = r["series"]
        b.plot(s["time_s"], s["com_vel_mps"][:, 0], lw=0.5)
    b.set(xlabel="time (s)", ylabel="CoM forward velocity (m/s)")


def _terrain(result, rows, axes):
    a, b = axes
    for r in rows:
        s = r["series"]
        a.plot(s["com_m"][:, 0], s["com_m"][:, 1], lw=0.7, label=r["label"]["terrain"])
        b.plot(s["time_s"], s["com_vel_mps"][:, 0], lw=0.5)
    a.set(xlabel="CoM x (m)", ylabel="CoM y (m)", title="rough ground (Fig. 5D)")
    a.legend(fontsize=6)
    b.set(xlabel="time (s)", ylabel="CoM forward velocity (m/s)")


def icp_path_m(series) -> np.ndarray:
    """(n-1, 2) the ground-truth capture point ``x + xd / omega`` of a walk's series (seed 004 eq. 1), omega
    from the walk's mean CoM height: CoM midpoints between records and their difference velocities."""
    com = np.asarray(series["com_m"], np.float64)
    if len(com) < 2:
        return np.zeros((0, 2))
    omega = np.sqrt(9.81 / com[:, 2].mean())
    return 0.5 * (com[1:, :2] + com[:-1, :2]) + np.asarray(series["com_vel_mps"]) / omega


def _flat(result, rows, axes):
    a, b = axes
    for k, r in enumerate(rows):
        s = r["series"]
        a.plot(s["time_s"], s["com_m"][: len(s["time_s"]), 2], lw=0.7)
        b.plot(s["com_m"][:, 0], s["com_m"][:, 1], lw=0.7, color=f"C{k}", label=f"CoM {r['label']}")
        icp = icp_path_m(s)
        b.plot(icp[:, 0], icp[:, 1], lw=0.5, ls="--", color=f"C{k}", label="ICP (ground truth)")
    x = rows[0] if rows else {}
    knee = x.get("stance_knee_mid_rad")
    a.set(xlabel="time (s)", ylabel="CoM height (m)",
          title=f"stance knee at mid-stance {knee:.3f} rad" if knee is not None else "CoM height (Fig. 9)")
    b.set(xlabel="x (m)", ylabel="y (m)", title="CoM and ICP paths (Fig. 9)")
    b.legend(fontsize=5)


def _mid_swing_push(result, rows, axes):
    a, b = axes
    _polar_ok(result, a, "impulse_ns", "impulse (N s): o recovered, x fell")
    per = result["by_direction_deg"]
    degs = sorted(int(d) for d in per)
    best = [per[str(d)]["largest_recovered_ns"] or 0.0 for d in degs]
    b.plot([math.radians(d) for d in degs + degs[:1]], best + best[:1], "-o", ms=3)
    b.set_title("largest recovered impulse (N s) by direction", fontsize=8)


def _toe_off(result, rows, axes):
    a, b = axes
    flat = [r for r in rows if r["label"].get("terrain", "flat") == "flat"]
    stairs = [r for r in rows if r["label"].get("terrain", "flat") != "flat"]
    value = lambda r, key: r.get(key) if r.get(key) is not None else float("nan")  # noqa: E731
    for key, ax, unit in (("stance_knee_mid_rad", a, "rad"), ("toe_off_fraction", b, "")):
        ax.plot([r["label"]["speed_mps"] for r in flat], [value(r, key) for r in flat], "-o", ms=3, label="flat")
        for r in stairs:
            ax.plot([r["label"]["speed_mps"]], [value(r, key)], "v", ms=5, label=r["label"]["terrain"])
        ax.set(xlabel="commanded speed (m/s)", ylabel=f"{key} ({unit})" if unit else key)
        ax.legend(fontsize=6)
    a.set_title("stance knee at mid-stance", fontsize=8)
    b.set_title("steps with toe-off (ground truth)", fontsize=8)


def _stairs(result, rows, axes):
    a, b = axes
    for r in rows:
        s = r["series"]
        a.plot(s["com_m"][:, 0], s["com_m"][:, 2], lw=0.7, label=f"{r['label']['riser_cm']} cm")
        b.plot(s["time_s"], s["com_vel_mps"][:, 0], lw=0.5)
    a.set(xlabel="CoM x (m)", ylabel="CoM z (m)", title=f"stairs (Fig. 10): largest riser up "
                                                          f"{result['largest_riser_up_cm']} cm, down "
                                                          f"{result.get('largest_riser_down_cm')} cm")
    a.legend(fontsize=6)
    b.set(xlabel="time (s)", ylabel="CoM forward velocity (m/s)")


DRAW = {
    "flat": _flat, "mid-swing-push": _mid_swing_push, "toe-off": _toe_off, "stairs": _stairs,
    "speeds": _speeds, "steer": _steer, "push": _push, "terrain": _terrain,
    "model-error": lambda res, rows, ax: _largest(res, rows, ax, "payload_kg", "kg"),
    "slope": lambda res, rows, ax: _largest(res, rows, ax, "slope_deg", "deg"),
    "noise": lambda res, rows, ax: _largest(res, rows, ax, "imu_noise_deg", "deg"),
    "delay": lambda res, rows, ax: _largest(res, rows, ax, "delay_ms", "ms"),
    "actuators": lambda res, rows, ax: _largest(res, rows, ax, "lag_s", "s"),
}


def figure(result: dict, rows: list):
    """A two-panel figure of an experiment's result (``rows``: :func:`mjx_coman.studies.run`'s)."""
    import matplotlib.pyplot as plt

    polar = result["experiment"] in ("push", "mid-swing-push")
    fig = plt.figure(figsize=(10, 4))
    axes = [fig.add_subplot(1, 2, i + 1, projection="polar" if polar else None) for i in range(2)]
    DRAW[result["experiment"]](result, rows, axes)
    fig.suptitle(f"{result['controller']}: {result['experiment']} ({result['size']})", fontsize=9)
    fig.tight_layout()
    return fig


def save(result: dict, rows: list, path: str) -> None:
    """The figure written to ``path`` (Agg backend)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = figure(result, rows)
    fig.savefig(path, dpi=120)
    plt.close(fig)
