"""NumPy baselines of ``bench/3lp_closed_loop.py``: the time-projection closed loop of the 3LP, recomputed from
matrix exponentials at every tick for one rollout (:class:`Baseline`), and vectorized over the batch with a
per-call plan (:class:`VectorizedBaseline`); the pushes both benches run."""

from __future__ import annotations

import math
import time

import numpy as np
import scipy
import scipy.linalg

from jaxlp import control, gait as gait_mod
from jaxlp.dynamics import N_AUG, N_Q, generator
from jaxlp.simulate import SimSpec, make_limits

PUSH_DURATION_S = 0.1
# The push of the baseline and of batch 1: mid-phase (step 1, 0.3 of it), off the tick grid, both axes.
CHECK_PUSH = dict(start_s=0.5213, force_n=90.0, direction_rad=0.6)
PELVIS_TOLERANCE_M = 1e-3
N_CHECK = 64  # rollouts per batch whose whole pelvis trajectories are compared, JAX against vectorized NumPy
# float32 JAX against float64 NumPy: a rollout on the verge of a fall amplifies rounding (at 5 steps, one in
# 1543 that did not fall ended 1.9 mm apart, the rest within 0.3 mm), so the check is on the share within tolerance
VECTORIZED_SHARE = 0.99


def _pushes(n: int, total_s: float):
    """``n`` pushes spread over start times, forces and headings (the first is CHECK_PUSH)."""
    rng = np.random.default_rng(0)
    start = rng.uniform(0.0, max(total_s - PUSH_DURATION_S, 0.0), n)
    force = rng.uniform(0.0, 150.0, n)
    direction = rng.uniform(-np.pi, np.pi, n)
    start[0], force[0], direction[0] = CHECK_PUSH["start_s"], CHECK_PUSH["force_n"], CHECK_PUSH["direction_rad"]
    return start, force, direction


M_ERR = np.asarray(control.M_ERR, float)
M_HAT = np.asarray(control.M_HAT, float)


class Baseline:
    """The time-projection closed loop, recomputed from matrix exponentials at every tick (one rollout)."""

    def __init__(self, params, spec: SimSpec):
        self.spec = spec
        g = gait_mod.periodic_gait(params, spec.step_time_s, 0.0, None)
        self.q0 = np.asarray(g.q0, float)  # (2, 6)
        self.u_nom = np.asarray(g.u, float)  # (2, 2)
        self.K = np.stack([np.asarray(control.constrained_dlqr(params, spec.step_time_s, lateral=lat).K, float)
                           for lat in (False, True)])  # (2, 2, 4)
        self.G = np.stack([np.asarray(generator(params, lat), float) for lat in (False, True)])  # (2, 12, 12)
        lim = make_limits()
        self.max_tau = float(lim.max_hip_torque_nm)
        self.max_lean = float(lim.max_lean_ratio) * float(params.h1)
        self.max_step = float(lim.max_step_ratio) * float(params.h1)

    def run(self, start_s, force_n, direction_rad, n_steps: int) -> np.ndarray:
        """Pelvis positions (n_steps * ticks, 2) after each tick."""
        sp = self.spec
        n, dt, T = sp.ticks_per_step, sp.dt_s, sp.step_time_s
        q = self.q0.copy()
        d = 1.0
        fallen = False
        pelvis = np.empty((n_steps * n, 2))
        heading = np.array([math.cos(direction_rad), math.sin(direction_rad)])
        eye2, zeros24 = np.eye(2), np.zeros((2, 4))
        for step in range(n_steps):
            for k in range(n):
                t = k * dt
                now = step * T + t
                sign = np.array([1.0, d])
                q_new = np.empty((2, N_Q))
                tau_all = np.empty(2)
                for ax in range(2):
                    # within-phase map from the phase start to now (seed 000, eq. 5, 16)
                    phi = scipy.linalg.expm(self.G[ax] * t)
                    A_t, B_t = phi[:N_Q, :N_Q], phi[:N_Q, 6:8]
                    nominal = (A_t @ self.q0[ax] + B_t @ self.u_nom[ax] + phi[:N_Q, 11]) * sign[ax]
                    e = sign[ax] * (M_ERR @ (q[ax] - nominal))
                    # time projection (seed 000, eq. 18)
                    system = np.block([[M_ERR @ A_t @ M_HAT, M_ERR @ B_t], [self.K[ax], eye2]])
                    sol = np.linalg.solve(system, np.concatenate([e, np.zeros(2)]))
                    dU = sol[4:6] * sign[ax]
                    tau = sign[ax] * (self.u_nom[ax, 0] + t * self.u_nom[ax, 1]) + dU[0] + t * dU[1]
                    rate = sign[ax] * self.u_nom[ax, 1] + dU[1]
                    if abs(tau) > self.max_tau:
                        tau, rate = math.copysign(self.max_tau, tau), 0.0
                    overlap = min(max(min(now + dt, start_s + PUSH_DURATION_S) - max(now, start_s), 0.0), dt)
                    z = np.zeros(N_AUG)
                    z[:N_Q], z[6], z[7] = q[ax], tau, rate
                    z[10], z[11] = force_n * overlap / dt * heading[ax], d
                    q_new[ax] = (scipy.linalg.expm(self.G[ax] * dt) @ z)[:N_Q]  # tick map
                    tau_all[ax] = tau
                bad = bool(np.any(np.abs(q_new[:, 1] - q_new[:, 2]) > self.max_lean) or not np.all(np.isfinite(q_new)))
                fallen = fallen or bad
                if not fallen:
                    q = q_new
                pelvis[step * n + k] = q[:, 1]
            # landing: the feet swap roles
            was_fallen = fallen
            if abs(q[0, 0] - q[0, 2]) > self.max_step:
                fallen = True
            if not was_fallen:
                q = np.stack([q[:, 2], q[:, 1], q[:, 0], np.zeros(2), q[:, 4], np.zeros(2)], axis=1)
            d = -d
        return pelvis


class VectorizedBaseline(Baseline):
    """The same closed loop in NumPy (float64), vectorized over the batch: a reasonable NumPy port.

    Per call, the plan (as :func:`jaxlp.simulate.make_plan`, with SciPy): for every tick of a phase,
    ``exp(G t)`` (one batched ``scipy.linalg.expm``) gives the nominal state and, through eq. 18 (one
    batched ``numpy.linalg.solve``), the projection gain ``P(t)`` with ``dU = P(t) e(t)``; ``exp(G dt)``
    the tick map. Then one Python loop over the ticks, each tick a dozen array operations on all
    rollouts at once (the state laid out ``(2 axes, 6, batch)``: each map one ``matmul`` per axis, the
    masks along the contiguous batch axis).
    The gait, the DLQR gains ``K`` and the generators ``G`` come from :mod:`jaxlp`, as for :class:`Baseline`.
    """

    def plan(self):
        """``(gains (2, n, 2, 6) of [tau, rate] on q, their offsets (2, n, 2) from the nominal (d = +1), tick map)``."""
        sp = self.spec
        ts = np.arange(sp.ticks_per_step) * sp.dt_s
        phi = scipy.linalg.expm(self.G[:, None] * ts[None, :, None, None])  # (2 axes, n, 12, 12)
        A, B = phi[..., :N_Q, :N_Q], phi[..., :N_Q, 6:8]
        nominal = (A @ self.q0[:, None, :, None] + B @ self.u_nom[:, None, :, None])[..., 0] + phi[..., :N_Q, 11]
        K = np.broadcast_to(self.K[:, None], (2, len(ts), 2, 4))
        system = np.concatenate([np.concatenate([M_ERR @ A @ M_HAT, M_ERR @ B], -1),
                                 np.concatenate([K, np.broadcast_to(np.eye(2), K.shape[:2] + (2, 2))], -1)], -2)
        rhs = np.broadcast_to(np.concatenate([np.eye(4), np.zeros((2, 4))]), system.shape[:2] + (6, 4))
        P = np.linalg.solve(system, rhs)[..., 4:6, :] @ M_ERR  # (2, n, 2, 6): dU = P (q - nominal), eq. 18
        # tau = sign u_c + t sign u_r + dU_c + t dU_r; rate = sign u_r + dU_r: gains of [tau, rate] on q - nominal
        gains = np.stack([P[..., 0, :] + ts[None, :, None] * P[..., 1, :], P[..., 1, :]], axis=-2)
        offsets = np.einsum("akij,akj->aki", gains, nominal)  # gains (q - nominal) = gains q - offsets
        return gains, offsets, scipy.linalg.expm(self.G * sp.dt_s)

    def run_batch(self, start_s, force_n, direction_rad, n_steps: int):
        """Pelvis, swing and stance positions and hip torques, (ticks, 2, batch) each, and ``fell`` (batch,)."""
        sp = self.spec
        n, dt, T = sp.ticks_per_step, sp.dt_s, sp.step_time_s
        gains, offsets, tick = self.plan()
        flow_q = np.ascontiguousarray(tick[:, :N_Q, :N_Q])  # (2, 6, 6)
        flow_in = np.ascontiguousarray(tick[:, :N_Q, [6, 7, 10, 11]])  # (2, 6, 4): tau, rate, push force, d
        ones = np.ones(N_Q)
        start_s, force_n = np.asarray(start_s, float), np.asarray(force_n, float)
        nb = start_s.shape[0]
        heading = np.stack([np.cos(direction_rad), np.sin(direction_rad)])  # (2, batch)
        q = np.repeat(self.q0[:, :, None], nb, axis=2)  # (2 axes, 6, batch): the batch along rows
        fallen = np.zeros(nb, bool)
        inputs = np.empty((2, 4, nb))
        out = np.empty((4, n_steps * n, 2, nb))  # pelvis, swing, stance, tau
        d = 1.0
        for step in range(n_steps):
            sign = np.array([1.0, d])
            tau_ff = sign[:, None] * self.u_nom[:, 0:1]  # feed-forward torque at t = 0 and its rate, (2, 1)
            rate_ff = sign[:, None] * self.u_nom[:, 1:2]
            for k in range(n):
                t = k * dt
                now = step * T + t
                u = gains[:, k] @ q - (offsets[:, k] * sign[:, None])[:, :, None]  # (2, 2, batch): time projection
                tau = tau_ff + t * rate_ff + u[:, 0]
                saturated = np.abs(tau) > self.max_tau
                np.clip(tau, -self.max_tau, self.max_tau, out=inputs[:, 0])
                np.copyto(inputs[:, 1], np.where(saturated, 0.0, rate_ff + u[:, 1]))
                overlap = np.clip(np.minimum(now + dt, start_s + PUSH_DURATION_S) - np.maximum(now, start_s), 0.0, dt)
                np.multiply(force_n * overlap / dt, heading, out=inputs[:, 2])
                inputs[:, 3] = d
                q_new = flow_q @ q + flow_in @ inputs
                bad = np.any(np.abs(q_new[:, 1] - q_new[:, 2]) > self.max_lean, axis=0)
                bad |= ~np.all(np.isfinite(ones @ q_new), axis=0)  # a column sum is finite iff its terms are
                fallen |= bad
                np.copyto(q_new, q, where=fallen)  # frozen where fallen
                q = q_new
                i = step * n + k
                out[0, i], out[1, i], out[2, i], out[3, i] = q[:, 1], q[:, 0], q[:, 2], inputs[:, 0]
            # landing: the feet swap roles
            was_fallen = fallen.copy()
            fallen |= np.abs(q[0, 0] - q[0, 2]) > self.max_step
            zero = np.zeros_like(q[:, 0])
            swapped = np.stack([q[:, 2], q[:, 1], q[:, 0], zero, q[:, 4], zero], axis=1)
            q = np.where(was_fallen, q, swapped)
            d = -d
        return out, fallen


def bench_vectorized(base: VectorizedBaseline, n_steps: int, batches, repeats: int) -> dict:
    """Wall seconds (best of ``repeats``, plan included) of the vectorized baseline per batch, and its results."""
    out = {}
    for nb in batches:
        start, force, direction = _pushes(nb, n_steps * base.spec.step_time_s)
        best, res = math.inf, None
        for _ in range(repeats):
            res = None
            t0 = time.perf_counter()
            res = base.run_batch(start, force, direction, n_steps)
            best = min(best, time.perf_counter() - t0)
        traj, fell = res
        out[nb] = dict(seconds=best, pelvis=np.moveaxis(traj[0, :, :, :N_CHECK], -1, 0), final=traj[0, -1].T,
                       fell=fell)
    return out


def bench_baseline(base: Baseline, n_steps: int, repeats: int):
    best, pel = math.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        pel = base.run(CHECK_PUSH["start_s"], CHECK_PUSH["force_n"], CHECK_PUSH["direction_rad"], n_steps)
        best = min(best, time.perf_counter() - t0)
    return best, pel


# ---------------------------------------------------------------------------- main
