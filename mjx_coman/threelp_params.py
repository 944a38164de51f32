"""3LP parameters of the simulated COMAN, derived from its MJCF.

The 3LP model (seed 000, "3LP Model") lumps the robot into a torso point mass
on a massless pelvis and two legs. Here every number comes from the compiled
MuJoCo model in its zero pose (legs straight, sole flat at the bottom):

* ``m2``: one leg (hip motor, upper and lower thigh, shank, ankle motor, foot);
* ``h1``: hip axis height above the sole;
* ``h2``: leg CoM depth below the hip axis;
* ``I2``: leg pitch inertia about its CoM (bodies' own inertias plus the
  parallel-axis terms in the sagittal plane);
* ``m1``: everything else (pelvis, waist, torso, arms, IMU); the 3LP pelvis is
  massless, so the pelvis link's mass goes to the torso;
* ``h3``: CoM height of ``m1`` above the hip line;
* ``pw``: half the hip spacing (lateral offset of the hip roll axis).
"""

from __future__ import annotations

import mujoco
import numpy as np

from jaxlp.params import GRAVITY_MPS2, ThreeLPParams, make_params

LEG_LINKS = ("HipMot", "ThighUpLeg", "ThighLowLeg", "LowLeg", "Footmot", "Foot")


def leg_body_names(side: str) -> tuple[str, ...]:
    """Body names of one leg, ``side`` in ``{"R", "L"}``."""
    if side not in ("R", "L"):
        raise ValueError(f"side must be 'R' or 'L', got {side!r}")
    return tuple(side + n for n in LEG_LINKS)


def mjcf_segments(model: mujoco.MjModel | None = None) -> dict[str, float]:
    """Masses and lengths of COMAN measured on the MJCF in its zero pose.

    Returns:
        a dict with the 3LP quantities (``m1, m2, h1, h2, h3, I2, pw``) plus
        ``total_mass_kg`` and ``leg_mass_left_kg`` (symmetry check).
    """
    if model is None:
        from mjx_coman import load_model

        model = load_model()
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)

    def bid(name: str) -> int:
        return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)

    mass = model.body_mass
    com = data.xipos  # body CoM in world
    sole_z = data.site("r_sole").xpos[2]
    hip = data.xpos[bid("RThighUpLeg")]  # hip roll/yaw/pitch axes meet here (y = -pw)
    hip_z = data.xpos[bid("Waist")][2]

    leg = [bid(n) for n in leg_body_names("R")]
    m2 = float(mass[leg].sum())
    leg_com = (mass[leg, None] * com[leg]).sum(0) / m2
    inertia_yy = 0.0
    for b in leg:
        rot = data.ximat[b].reshape(3, 3)
        i_world = rot @ np.diag(model.body_inertia[b]) @ rot.T
        dx, dz = com[b, 0] - leg_com[0], com[b, 2] - leg_com[2]
        inertia_yy += i_world[1, 1] + mass[b] * (dx * dx + dz * dz)

    legs = set(leg) | {bid(n) for n in leg_body_names("L")}
    upper = [b for b in range(1, model.nbody) if b not in legs]
    m1 = float(mass[upper].sum())
    upper_com = (mass[upper, None] * com[upper]).sum(0) / m1
    return dict(
        m1=m1,
        m2=m2,
        h1=float(hip_z - sole_z),
        h2=float(hip_z - leg_com[2]),
        h3=float(upper_com[2] - hip_z),
        I2=float(inertia_yy),
        pw=float(abs(hip[1])),
        total_mass_kg=float(mass[1:].sum()),
        leg_mass_left_kg=float(mass[[bid(n) for n in leg_body_names("L")]].sum()),
    )


def coman_mjcf_params(g: float = GRAVITY_MPS2) -> ThreeLPParams:
    """Validated 3LP parameters of the simulated COMAN (robot ``coman-mjcf``).

    Args:
        g: gravity, m/s^2.

    Returns:
        :class:`jaxlp.params.ThreeLPParams` built by ``make_params``.

    Raises:
        ValueError: ``g`` not positive (from ``make_params``).
    """
    s = mjcf_segments()
    return make_params(m1=s["m1"], m2=s["m2"], h1=s["h1"], h2=s["h2"], h3=s["h3"], I2=s["I2"], pw=s["pw"], g=g)
