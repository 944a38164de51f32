"""Discrete error dynamics and the constrained DLQR of 3LP walking.

Seed 000, eq. 11-14; brief section 5. Per axis the error is
``e = [s1, s2, s1_dot, s2_dot]``: the swing and pelvis positions relative to
the stance foot and their velocities, minus the nominal gait. An error at
phase start, with a correction ``dU = [du_c, du_r]`` of the hip torque,
propagates through a phase and the foot exchange to ``E[k+1] = A_hat E[k] +
B_hat dU[k]`` with the swing foot landing at zero velocity (``C_hat E[k+1] =
0``). Solving that constraint for ``du_r`` leaves an ordinary DLQR for
``du_c``, solved by a fixed number of Riccati iterations that ``jax.grad``
passes through.

Two conventions for the foot exchange (``exchange=``):

- ``"authors"`` (default; the seed authors' 3LP): the positions are
  re-expressed relative to the new stance foot, the velocity errors cross the
  exchange unchanged (new swing-velocity error = old one at the phase end,
  new pelvis-velocity error = old one). The open-loop sagittal map then has
  the eigenvalue 1 of translation invariance.
- ``"relative"``: everything is re-expressed relative to the landing foot
  (new swing velocity = -old swing velocity, new pelvis velocity = old pelvis
  velocity - old swing velocity).

Both agree whenever the swing foot lands at rest, so the constrained map, the
gains and the closed loop are the same; only the open-loop map differs.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxlp.dynamics import N_Q, transition
from jaxlp.params import ThreeLPParams, _check_positive

# e = M q, q = M_hat e (stance foot error zero); S swaps swing and stance feet.
M_ERR = jnp.array(
    [
        [1.0, 0.0, -1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, -1.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 1.0, 0.0, -1.0],
        [0.0, 0.0, 0.0, 0.0, 1.0, -1.0],
    ]
)
M_HAT = jnp.array(
    [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
        [0.0, 0.0, 0.0, 0.0],
    ]
)
SWAP = jnp.eye(N_Q)[jnp.array([2, 1, 0, 5, 4, 3])]
# The authors' exchange: positions relative to the new stance foot (the old
# swing foot), velocities carried over.
EXCHANGE_AUTHORS = jnp.concatenate([(M_ERR @ SWAP)[:2], M_ERR[2:]], axis=0)
EXCHANGES = ("authors", "relative")
C_HAT = jnp.array([0.0, 0.0, 1.0, 0.0])  # the landing velocity of the swing foot
ERROR_NAMES = ("swing_position", "pelvis_position", "swing_velocity", "pelvis_velocity")


def mirror_sign(lateral: bool) -> float:
    """The symmetry ``O`` of seed 000, eq. 8: +1 sagittal, -1 lateral."""
    return -1.0 if lateral else 1.0


COST_FORMS = ("authors", "diagonal")


@functools.partial(jax.tree_util.register_dataclass, data_fields=["position", "velocity", "torque"],
                   meta_fields=["form"])
@dataclasses.dataclass(frozen=True)
class LQRWeights:
    """Quadratic cost weights of the DLQR (brief section 5).

    Attributes:
        position: weight of the position errors, 1/m^2.
        velocity: weight of the velocity errors, s^2/m^2.
        torque: weight of the constant hip-torque correction, 1/(N m)^2.
        form: ``"authors"``: ``position [(p - s)^2 + (p - a)^2] + velocity
            p_dot^2`` (the seed authors' cost: pelvis-to-feet distances, no
            swing-velocity cost); ``"diagonal"``: ``position (e1^2 + e2^2) +
            velocity (e1_dot^2 + e2_dot^2)``.
    """

    position: jax.Array
    velocity: jax.Array
    torque: jax.Array
    form: str = "authors"

    def state_matrix(self) -> jax.Array:
        """``Q`` of ``E^T Q E`` for ``E = [s - a, p - a, s_dot, p_dot]``."""
        if self.form == "diagonal":
            return jnp.diag(jnp.stack([self.position, self.position, self.velocity, self.velocity]))
        z = jnp.zeros_like(self.position)
        pos = self.position * jnp.array([[1.0, -1.0], [-1.0, 2.0]])  # (e2 - e1)^2 + e2^2
        top = jnp.concatenate([pos, jnp.zeros((2, 2), pos.dtype)], axis=1)
        bottom = jnp.stack([jnp.stack([z, z, z, z]), jnp.stack([z, z, z, self.velocity])])
        return jnp.concatenate([top, bottom], axis=0)

    def scaled(self, scale) -> "LQRWeights":
        """The weights multiplied by ``scale = (position, velocity, torque)`` factors."""
        return dataclasses.replace(self, position=self.position * scale[0], velocity=self.velocity * scale[1],
                                   torque=self.torque * scale[2])


def default_weights(params: ThreeLPParams) -> LQRWeights:
    """The seed authors' cost: positions by ``1/h1^2``, the pelvis velocity by ``1/(g h1)``,
    the torque by ``1/(M g)^2`` with ``M`` the robot's total mass (COMAN 28.5 kg)."""
    M = params.total_mass_kg
    return LQRWeights(
        position=1.0 / params.h1**2,
        velocity=1.0 / (params.g * params.h1),
        torque=1.0 / (M * params.g) ** 2,
    )


def diagonal_weights(params: ThreeLPParams) -> LQRWeights:
    """The alternative diagonal cost: each error by ``1/h1^2`` or ``1/(g h1)``, the torque by
    ``1/((m1 + 2 m2) g)^2``."""
    return dataclasses.replace(default_weights(params), torque=1.0 / (params.model_mass_kg * params.g) ** 2,
                               form="diagonal")


def make_weights(position: float, velocity: float, torque: float, form: str = "authors") -> LQRWeights:
    """Validated weights. Raises ``ValueError`` for a non-positive weight or an unknown form."""
    for name, val in (("position", position), ("velocity", velocity), ("torque", torque)):
        _check_positive(f"weight {name}", val)
    if form not in COST_FORMS:
        raise ValueError(f"cost form must be one of {', '.join(COST_FORMS)}, got {form!r}")
    return LQRWeights(jnp.asarray(position, float), jnp.asarray(velocity, float), jnp.asarray(torque, float), form)


class ErrorMap(NamedTuple):
    """``E[k+1] = A E[k] + B dU[k]``, one axis (seed 000, eq. 13-14)."""

    A: jax.Array  # (4, 4)
    B: jax.Array  # (4, 2)


def exchange_matrix(exchange: str = "authors") -> jax.Array:
    """(4, 6) map of the phase-end state ``q`` to the next phase's error (see the module docstring).

    Raises:
        ValueError: an unknown convention.
    """
    if exchange == "authors":
        return EXCHANGE_AUTHORS
    if exchange == "relative":
        return M_ERR @ SWAP
    raise ValueError(f"exchange must be one of {', '.join(EXCHANGES)}, got {exchange!r}")


def step_error_map(params: ThreeLPParams, step_time_s, lateral: bool = False, exchange: str = "authors") -> ErrorMap:
    """The step-to-step error map ``A_hat = O X A(T) M_hat``, ``B_hat = O X B(T)`` (seed 000, eq. 14).

    ``X`` is the foot exchange of :func:`exchange_matrix`; ``O`` the mirror of eq. 8.
    """
    tr = transition(params, step_time_s, lateral)
    X = mirror_sign(lateral) * exchange_matrix(exchange)
    return ErrorMap(A=X @ tr.A @ M_HAT, B=X @ tr.B)


def within_phase_map(params: ThreeLPParams, t, lateral: bool = False) -> ErrorMap:
    """Error at time ``t`` of a phase from the error and correction at its start (seed 000, eq. 16)."""
    tr = transition(params, t, lateral)
    return ErrorMap(A=M_ERR @ tr.A @ M_HAT, B=M_ERR @ tr.B)


class Reduced(NamedTuple):
    """The error map with the landing-velocity constraint eliminated.

    ``du_r = R_e E + R_c du_c`` keeps ``C_hat E[k+1] = 0``; then
    ``E[k+1] = A E + B du_c``.
    """

    A: jax.Array  # (4, 4)
    B: jax.Array  # (4, 1)
    R_e: jax.Array  # (4,)
    R_c: jax.Array  # ()


def eliminate_landing_constraint(emap: ErrorMap) -> Reduced:
    """Solve ``C_hat (A_hat E + B_hat dU) = 0`` for the ramp ``du_r`` (brief section 5)."""
    a = C_HAT @ emap.A
    bc, br = C_HAT @ emap.B
    R_e = -a / br
    R_c = -bc / br
    A = emap.A + jnp.outer(emap.B[:, 1], R_e)
    B = (emap.B[:, 0] + emap.B[:, 1] * R_c)[:, None]
    return Reduced(A=A, B=B, R_e=R_e, R_c=R_c)


def riccati(A, B, Q, R, iterations: int = 400) -> jax.Array:
    """Fixed-point iteration of the discrete algebraic Riccati equation.

    ``P <- Q + A^T P A - A^T P B (R + B^T P B)^-1 B^T P A``, a static number of
    times (differentiable with ``jax.grad``).
    """

    def body(_, P):
        BtPA = B.T @ P @ A
        gain = jnp.linalg.solve(R + B.T @ P @ B, BtPA)
        P_new = Q + A.T @ P @ A - BtPA.T @ gain
        return 0.5 * (P_new + P_new.T)

    return jax.lax.fori_loop(0, iterations, body, Q)


class DLQR(NamedTuple):
    """A constrained DLQR of one axis: ``dU = -K E`` with ``K`` (2, 4) for ``[du_c, du_r]``."""

    K: jax.Array
    P: jax.Array
    emap: ErrorMap


def constrained_dlqr(
    params: ThreeLPParams,
    step_time_s,
    weights: LQRWeights | None = None,
    lateral: bool = False,
    iterations: int = 400,
    exchange: str = "authors",
) -> DLQR:
    """DLQR of the step-to-step error map with zero-velocity landing (brief section 5).

    Args:
        params: 3LP parameters.
        step_time_s: step time, s.
        weights: cost weights; :func:`default_weights` if ``None``.
        lateral: the lateral axis instead of the sagittal one.
        iterations: Riccati iterations (static).
        exchange: the foot-exchange convention of the returned error map (the
            gain does not depend on it).

    Returns:
        The gain ``K`` with ``dU[k] = -K E[k]`` (constant and ramp parts), the
        Riccati solution and the unconstrained error map.
    """
    if weights is None:
        weights = default_weights(params)
    emap = step_error_map(params, step_time_s, lateral, exchange)
    red = eliminate_landing_constraint(emap)
    Q = weights.state_matrix()
    R = jnp.reshape(weights.torque, (1, 1))
    P = riccati(red.A, red.B, Q, R, iterations)
    Kc = jnp.linalg.solve(R + red.B.T @ P @ red.B, red.B.T @ P @ red.A)  # (1, 4)
    Kr = red.R_c * Kc[0] - red.R_e  # du_r = R_e E + R_c du_c = -Kr E
    return DLQR(K=jnp.stack([Kc[0], Kr]), P=P, emap=emap)


def closed_loop_map(ctrl: DLQR) -> jax.Array:
    """``A_hat - B_hat K``: the step-to-step error map under the DLQR."""
    return ctrl.emap.A - ctrl.emap.B @ ctrl.K
