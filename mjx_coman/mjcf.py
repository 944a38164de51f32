"""Build the MJCF model of COMAN from the link and joint tables.

The tables (``mjx_coman/data/links.csv`` and ``joints.csv``, copied from the
project's COMAN brief) give each link's CAD mass, CoM and full inertia, and
each joint's frame offset (no rotations, except the IMU mount), axis and
limits. :func:`build_xml` turns them into two files:

* ``assets/coman.xml``: the robot (free-floating ``Waist``, 23 hinge joints,
  one torque motor per joint, sites for soles, ankle F/T sensors, foot
  corners and the IMU);
* ``assets/scene.xml``: floor and light, the robot included, and the only
  collisions of the model: eight explicit ``<pair>`` elements between the
  floor and the four sole-corner spheres of each foot.

Every other geom has ``contype = conaffinity = 0`` so that MJX checks only
those eight pairs. Link joints carry a small armature; the motors (with their
reflected rotor inertia) are simulated outside MuJoCo by
:mod:`mjx_coman.actuators`, except that joints without a series spring get the
reflected rotor inertia as armature (the motor is rigidly coupled there).

:func:`scene_xml` also writes the scene variants of :mod:`mjx_coman.scenarios`
(terrain, a gravity frame), whose extra bodies and geoms follow the robot's.

Run ``python -m mjx_coman.mjcf`` to regenerate the assets.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

DATA_DIR = Path(__file__).resolve().parent / "data"
ASSETS_DIR = Path(__file__).resolve().parent / "assets"

# Foot geometry (brief): sole 0.20 x 0.10 m, toe 0.13 m ahead of and heel
# 0.07 m behind the ankle axis, sole 0.09 m below it; F/T sensor 0.065 m below.
SOLE_BELOW_ANKLE_M = 0.09
TOE_AHEAD_M = 0.13
HEEL_BEHIND_M = 0.07
HALF_SOLE_WIDTH_M = 0.05
FT_BELOW_ANKLE_M = 0.065
CONTACT_SPHERE_RADIUS_M = 0.01

# Motor constants shared with the actuator model (seed 000, eq. 20).
ROTOR_INERTIA_NMS2_PER_RAD = 0.23
# Joints with a series elastic actuator (spring between motor and link).
SEA_JOINTS = ("RHipSag", "RKneeSag", "RAnkSag", "LHipSag", "LKneeSag", "LAnkSag")
LINK_ARMATURE_KGM2 = 1e-3  # small link-side armature for SEA joints

TIMESTEP_S = 0.001
FOOT_CORNERS = ("upper_left", "upper_right", "lower_left", "lower_right")


def _fmt(x: float) -> str:
    """Deterministic short float format (regeneration gives identical files)."""
    s = f"{float(x):.9g}"
    return "0" if s in ("-0", "0") else s


def _vec(v) -> str:
    return " ".join(_fmt(x) for x in v)


def read_links(path: Path | None = None) -> dict[str, dict]:
    """Read the link table: ``{name: {mass, com (3,), inertia (3, 3)}}``."""
    out = {}
    with open(path or DATA_DIR / "links.csv", newline="") as f:
        for r in csv.DictReader(f):
            v = {k: float(x) for k, x in r.items() if k != "link"}
            inertia = np.array(
                [
                    [v["ixx"], v["ixy"], v["ixz"]],
                    [v["ixy"], v["iyy"], v["iyz"]],
                    [v["ixz"], v["iyz"], v["izz"]],
                ]
            )
            out[r["link"]] = dict(
                mass=v["mass_kg"], com=np.array([v["com_x"], v["com_y"], v["com_z"]]), inertia=inertia
            )
    return out


def read_joints(path: Path | None = None) -> list[dict]:
    """Read the joint table as a list of dicts (floats parsed, blanks -> None)."""
    rows = []
    with open(path or DATA_DIR / "joints.csv", newline="") as f:
        for r in csv.DictReader(f):
            d = dict(r)
            for k in ("x", "y", "z", "roll", "pitch", "yaw", "axis_x", "axis_y", "axis_z", "lower_rad", "upper_rad"):
                d[k] = float(r[k]) if r[k] not in ("", None) else None
            rows.append(d)
    return rows


def fix_inertia(inertia: np.ndarray, min_moment: float = 1e-8) -> tuple[np.ndarray, bool]:
    """Make an inertia tensor positive definite and satisfy the triangle inequality.

    The fix is minimal: principal moments below ``min_moment`` are raised to
    it, and if the largest exceeds the sum of the other two the smaller two
    are raised together until equality; the principal axes are kept.

    Returns:
        the (possibly) fixed tensor and whether it was changed.
    """
    inertia = 0.5 * (inertia + inertia.T)
    w, v = np.linalg.eigh(inertia)
    w2 = np.maximum(w, min_moment)
    if w2[0] + w2[1] < w2[2]:
        deficit = w2[2] - w2[0] - w2[1]
        w2[0] += deficit / 2
        w2[1] += deficit / 2
    changed = not np.allclose(w, w2, rtol=0, atol=0)
    return (v @ np.diag(w2) @ v.T if changed else inertia), changed


def _inertial(link: dict) -> str:
    inertia, _ = fix_inertia(link["inertia"])
    full = [inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2]]
    return f'<inertial pos="{_vec(link["com"])}" mass="{_fmt(link["mass"])}" fullinertia="{_vec(full)}"/>'


def _rpy_to_quat(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return np.array(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


class _Writer:
    def __init__(self) -> None:
        self.lines: list[str] = []
        self.joint_order: list[str] = []  # hinge joints in tree (qpos) order

    def add(self, depth: int, text: str) -> None:
        self.lines.append("  " * depth + text)


def _children(joints: list[dict], parent: str) -> list[dict]:
    return [j for j in joints if j["parent"] == parent]


def _visual_capsule(w: _Writer, depth: int, offset: np.ndarray, rgba: str) -> None:
    if np.linalg.norm(offset) > 0.02:
        w.add(depth, f'<geom class="visual" type="capsule" size="0.018" fromto="0 0 0 {_vec(offset)}" rgba="{rgba}"/>')


def _foot_geoms(w: _Writer, depth: int, side: str) -> None:
    """Sole sites, F/T site, corner sites and the four contact spheres of a foot."""
    s = side.lower()[0]
    z = -SOLE_BELOW_ANKLE_M
    length = TOE_AHEAD_M + HEEL_BEHIND_M
    xc = (TOE_AHEAD_M - HEEL_BEHIND_M) / 2
    w.add(depth, f'<geom class="visual" type="box" size="{_vec([length / 2, HALF_SOLE_WIDTH_M, 0.005])}" '
                 f'pos="{_vec([xc, 0, z + 0.005])}" rgba="0.3 0.3 0.35 1"/>')
    w.add(depth, f'<site name="{s}_sole" pos="{_vec([0, 0, z])}" size="0.005"/>')
    w.add(depth, f'<site name="{s}_toe" pos="{_vec([TOE_AHEAD_M, 0, z])}" size="0.005"/>')
    w.add(depth, f'<site name="{s}_ankle" pos="0 0 0" size="0.005"/>')
    w.add(depth, f'<site name="{s}_ft" pos="{_vec([0, 0, -FT_BELOW_ANKLE_M])}" size="0.008"/>')
    corners = {
        "upper_left": (TOE_AHEAD_M, HALF_SOLE_WIDTH_M),
        "upper_right": (TOE_AHEAD_M, -HALF_SOLE_WIDTH_M),
        "lower_left": (-HEEL_BEHIND_M, HALF_SOLE_WIDTH_M),
        "lower_right": (-HEEL_BEHIND_M, -HALF_SOLE_WIDTH_M),
    }
    r = CONTACT_SPHERE_RADIUS_M
    for name in FOOT_CORNERS:
        x, y = corners[name]
        w.add(depth, f'<site name="{s}_foot_{name}" pos="{_vec([x, y, z])}" size="0.004"/>')
        # Sphere centre raised by its radius so that its bottom lies on the sole plane.
        w.add(depth, f'<geom name="{s}_foot_{name}_contact" class="foot_contact" type="sphere" size="{_fmt(r)}" '
                     f'pos="{_vec([x - math.copysign(r, x), y - math.copysign(r, y), z + r])}"/>')


def _body(w: _Writer, depth: int, name: str, links: dict, joints: list[dict], joint_row: dict | None) -> None:
    pos = [0.0, 0.0, 0.0] if joint_row is None else [joint_row["x"], joint_row["y"], joint_row["z"]]
    attrs = f'name="{name}" pos="{_vec(pos)}"'
    if joint_row is not None and any(joint_row[k] for k in ("roll", "pitch", "yaw")):
        attrs += f' quat="{_vec(_rpy_to_quat(joint_row["roll"], joint_row["pitch"], joint_row["yaw"]))}"'
    if joint_row is None:
        attrs += ' childclass="coman"'
    w.add(depth, f"<body {attrs}>")
    if joint_row is None:
        w.add(depth + 1, '<freejoint name="root"/>')
    elif joint_row["type"] == "revolute":
        w.joint_order.append(joint_row["joint"])
        axis = [joint_row["axis_x"], joint_row["axis_y"], joint_row["axis_z"]]
        arm = LINK_ARMATURE_KGM2 if joint_row["joint"] in SEA_JOINTS else ROTOR_INERTIA_NMS2_PER_RAD
        w.add(depth + 1, f'<joint name="{joint_row["joint"]}" axis="{_vec(axis)}" '
                         f'range="{_fmt(joint_row["lower_rad"])} {_fmt(joint_row["upper_rad"])}" armature="{_fmt(arm)}"/>')
    if name in links:
        w.add(depth + 1, _inertial(links[name]))
    rgba = "0.75 0.75 0.8 1" if "Foot" not in name else "0.4 0.4 0.45 1"
    kids = _children(joints, name)
    for k in kids:
        if k["child"] in links:
            _visual_capsule(w, depth + 1, np.array([k["x"], k["y"], k["z"]]), rgba)
    if name == "Waist":
        w.add(depth + 1, '<site name="pelvis" pos="0 0 0" size="0.01"/>')
    if name == "DWYTorso":
        w.add(depth + 1, '<geom class="visual" type="box" size="0.06 0.09 0.1" pos="-0.03 0 0.11" rgba="0.8 0.8 0.85 1"/>')
    if name in ("RFoot", "LFoot"):
        _foot_geoms(w, depth + 1, name[0])
    # Fixed children that are links (forearm plates, IMU) become welded bodies;
    # fixed frames without mass (torso, gaze, wrists) become sites.
    order = {"Waist": ["RHipMot", "LHipMot", "DWL", "imu_link"]}.get(name)
    if order is not None:
        kids = sorted(kids, key=lambda k: order.index(k["child"]) if k["child"] in order else 99)
    for k in kids:
        if k["child"] in links:
            _body(w, depth + 1, k["child"], links, joints, k)
            continue
        if k["type"] == "fixed" and name not in ("RFoot", "LFoot"):
            w.add(depth + 1, f'<site name="{k["child"]}" pos="{_vec([k["x"], k["y"], k["z"]])}" size="0.006"/>')
    if name == "imu_link":
        w.add(depth + 1, '<site name="imu" pos="0 0 0" size="0.008"/>')
    w.add(depth, "</body>")


def build_xml(links_csv: Path | None = None, joints_csv: Path | None = None) -> tuple[str, str]:
    """Build the robot and scene MJCF texts from the two tables.

    Returns:
        ``(coman_xml, scene_xml)``; the scene includes ``coman.xml``.
    """
    links = read_links(links_csv)
    joints = read_joints(joints_csv)
    w = _Writer()
    w.add(0, '<mujoco model="coman">')
    w.add(1, '<compiler angle="radian" inertiafromgeom="false" autolimits="true"/>')
    w.add(1, f'<option timestep="{_fmt(TIMESTEP_S)}" integrator="Euler" solver="Newton" iterations="4" '
             'ls_iterations="8" cone="pyramidal">')
    w.add(2, '<flag eulerdamp="disable"/>')
    w.add(1, "</option>")
    w.add(1, "<default>")
    w.add(2, '<default class="coman">')
    w.add(3, '<joint type="hinge" damping="0" limited="true"/>')
    w.add(3, '<geom contype="0" conaffinity="0" group="1" density="0"/>')
    w.add(3, '<site group="3" rgba="0.9 0.2 0.2 1"/>')
    w.add(3, '<default class="visual"><geom contype="0" conaffinity="0" group="1"/></default>')
    w.add(3, '<default class="foot_contact"><geom contype="0" conaffinity="0" group="3" '
             'condim="3" friction="1 0.005 0.0001" rgba="0.9 0.5 0.1 1"/></default>')
    w.add(2, "</default>")
    w.add(2, '<motor ctrllimited="false" gear="1"/>')
    w.add(1, "</default>")
    w.add(1, "<worldbody>")
    _body(w, 2, "Waist", links, joints, None)
    w.add(1, "</worldbody>")
    # One torque motor per hinge, in qpos order: actuator i drives qpos[7 + i].
    w.add(1, "<actuator>")
    for name in w.joint_order:
        w.add(2, f'<motor name="{name}" joint="{name}"/>')
    w.add(1, "</actuator>")
    w.add(1, "</mujoco>")
    coman = "\n".join(w.lines) + "\n"
    return coman, scene_xml()


def foot_contact_geoms() -> tuple[str, ...]:
    """Names of the eight sole-corner contact spheres, right foot first (the order of the floor pairs)."""
    return tuple(f"{side}_foot_{name}_contact" for side in ("r", "l") for name in FOOT_CORNERS)


GRAVITY_FRAME_BODY = "gravity_frame"  # scene variants: the first body after the robot (see scene_xml)
TERRAIN_BODY = "terrain"


def scene_xml(include: str = "coman.xml", *, floor_contacts: bool = True, floor_z_m: float = 0.0,
              gravity_frame: bool = False, terrain_geoms: tuple[str, ...] = (), contact_geoms: tuple[str, ...] = (),
              assets: tuple[str, ...] = ()) -> str:
    """The scene MJCF: floor, light, the robot and its foot contacts; with no arguments the packaged ``scene.xml``.

    Scene variants (:mod:`mjx_coman.scenarios`) add, after the robot so that its body, geom and site ids
    stay those of the packaged model:

    * ``gravity_frame``: a massless static body :data:`GRAVITY_FRAME_BODY` whose orientation the scenario
      sets to the gravity-aligned frame (z against gravity), read by the sensors and the ground truth;
    * ``terrain_geoms``: geom elements (MJCF text) in a static body :data:`TERRAIN_BODY`, and an explicit
      ``<pair>`` between each of the ``contact_geoms`` (their names) and each foot sphere;
    * ``assets``: asset elements (e.g. an ``<hfield>``).

    Args:
        include: the robot file the scene includes (a path relative to the scene, or absolute).
        floor_contacts: pair the floor plane with the foot spheres (off when a terrain replaces it).
        floor_z_m: height of the floor plane.
    """
    if terrain_geoms and not gravity_frame:
        raise ValueError("terrain_geoms need gravity_frame=True (the terrain body follows the gravity frame)")
    s = _Writer()
    s.add(0, '<mujoco model="coman_scene">')
    s.add(1, f'<include file="{include}"/>')
    s.add(1, '<statistic center="0 0 0.5" extent="1.2"/>')
    s.add(1, '<visual><headlight diffuse="0.6 0.6 0.6" ambient="0.3 0.3 0.3"/></visual>')
    if assets:
        s.add(1, "<asset>")
        for a in assets:
            s.add(2, a)
        s.add(1, "</asset>")
    s.add(1, "<worldbody>")
    s.add(2, '<light name="sun" pos="0 0 3" dir="0 0 -1" directional="true"/>')
    pos = f' pos="0 0 {_fmt(floor_z_m)}"' if floor_z_m else ""
    s.add(2, f'<geom name="floor" type="plane" size="0 0 0.05"{pos} contype="0" conaffinity="0" rgba="0.8 0.8 0.8 1"/>')
    if gravity_frame:
        s.add(2, f'<body name="{GRAVITY_FRAME_BODY}"/>')
    if terrain_geoms:
        s.add(2, f'<body name="{TERRAIN_BODY}">')
        for g in terrain_geoms:
            s.add(3, g)
        s.add(2, "</body>")
    s.add(1, "</worldbody>")
    s.add(1, "<contact>")
    for geom in (("floor",) if floor_contacts else ()) + tuple(contact_geoms):
        for foot in foot_contact_geoms():
            s.add(2, f'<pair geom1="{geom}" geom2="{foot}" condim="3" friction="1 1 0.005 0.0001 0.0001"/>')
    s.add(1, "</contact>")
    s.add(1, "</mujoco>")
    return "\n".join(s.lines) + "\n"


def write_assets(out_dir: Path | None = None) -> tuple[Path, Path]:
    """Write ``coman.xml`` and ``scene.xml`` into ``out_dir`` (the package assets by default)."""
    out_dir = Path(out_dir or ASSETS_DIR)
    out_dir.mkdir(parents=True, exist_ok=True)
    coman, scene = build_xml()
    p1, p2 = out_dir / "coman.xml", out_dir / "scene.xml"
    p1.write_text(coman)
    p2.write_text(scene)
    return p1, p2


def main(argv=None) -> int:
    """``python -m mjx_coman.mjcf``: regenerate the MJCF and its tables; it takes no options."""
    from jaxlp.cliutil import Parser

    Parser(prog="python -m mjx_coman.mjcf", description="regenerate the COMAN MJCF and its tables").parse_args(argv)
    for p in write_assets():
        print(p)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
