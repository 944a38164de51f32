"""MuJoCo C ("native"): ``mj_step`` on the host for the whole batch, over a pool of threads.

Inside a jitted, vmapped rollout, a physics timestep is one ``jax.pure_callback`` for the whole batch
(``vmap_method="broadcast_all"``); the controller, the motors and the sensors stay the rollout's JAX code,
compiled once. The host splits the batch into one contiguous part per thread; MuJoCo releases the GIL in
``mj_step``, so the parts step in parallel.

A robot's step is a pure function of the arrays passed (``qpos``, ``qvel``, ``ctrl``, ``xfrc_applied``,
``qacc_warmstart``, the per-rollout model fields :data:`MODEL_FIELDS` and ``opt.gravity``), which are written
into the thread's own ``MjModel`` and ``MjData`` before its ``mj_step``: the result does not depend on the
thread, the order or the batch size.

What comes back: :data:`OUT_FIELDS`, and the contacts in MJX's layout (the contact slots ``mjx.collision``
makes for the model, :func:`contact_slots`): a C contact fills the next free slot of its geom pair, its
pyramid's constraint forces the slot's rows of ``efc_force`` (the other rows stay zero); an empty slot has
zero force and a distance of :data:`EMPTY_SLOT_DIST_M`. Other ``mjx.Data`` fields (``qacc``, ``cvel``,
``ximat``, ``geom_xpos``, the other constraint rows, ...) keep the values they had before the step. Nothing
is differentiable: a derivative through :meth:`NativeEngine.step` raises ``ValueError``.
"""

from __future__ import annotations

import concurrent.futures
import functools
import math
import os
import threading
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from jaxlp.host import host_eval
from mjx_coman.engines.base import Engine

# model fields a rollout may change (payloads, randomised masses, a scene's gravity frame), and opt.gravity
MODEL_FIELDS = ("body_mass", "body_ipos", "body_iquat", "body_inertia", "body_subtreemass", "body_invweight0",
                "dof_invweight0", "body_quat")
OUT_FIELDS = ("qpos", "qvel", "qacc_warmstart", "xpos", "xquat", "xmat", "xipos", "subtree_com", "site_xpos",
              "site_xmat")
CONTACT_FIELDS = ("pos", "frame", "dist", "friction")
EMPTY_SLOT_DIST_M = 1.0


class ContactSlots(NamedTuple):
    """MJX's contact layout of a model: each slot's geom pair, constraint rows and dimension."""

    geom: np.ndarray  # (n, 2)
    efc_address: np.ndarray  # (n,)
    dim: np.ndarray  # (n,)
    nefc: int
    efc_rows: int  # constraint rows of each slot (pyramid: 2 (dim - 1))
    pair_index: np.ndarray  # (ngeom, ngeom): the row of pair_slots of a geom pair, -1 if MJX does not collide it
    pair_slots: np.ndarray  # (pairs, most slots of a pair): each pair's slot indices in order, -1 padded

    @classmethod
    def of(cls, geom: np.ndarray, efc_address: np.ndarray, dim: np.ndarray, nefc: int, ngeom: int) -> "ContactSlots":
        """The layout of slots with these geom pairs ``(n, 2)``, first constraint rows and dimensions."""
        by_pair: dict = {}
        for s, (g1, g2) in enumerate(np.asarray(geom).tolist()):
            by_pair.setdefault((g1, g2), []).append(s)
        pair_index = np.full((ngeom, ngeom), -1, np.int64)
        pair_slots = np.full((max(len(by_pair), 1), max(map(len, by_pair.values()), default=1)), -1, np.int64)
        for p, ((g1, g2), slots) in enumerate(by_pair.items()):
            pair_index[g1, g2] = p
            pair_slots[p, :len(slots)] = slots
        return cls(np.asarray(geom), np.asarray(efc_address), np.asarray(dim), nefc, _rows(int(np.asarray(dim)[0])),
                   pair_index, pair_slots)


def contact_slots(mj_model: mujoco.MjModel) -> ContactSlots:
    """The contact slots ``mjx.collision`` fills for ``mj_model`` (one compilation, on the host)."""
    mx = mjx.put_model(mj_model)

    def collide(mx):
        d = mjx.collision(mx, mjx.make_data(mx))
        c = d._impl.contact
        return c.geom, c.efc_address, c.dim, d._impl.efc_force

    geom, addr, dim, efc = host_eval(collide, mx)
    dims = set(np.asarray(dim).tolist())
    if len(dims) != 1 or np.any(np.asarray(addr) < 0):
        raise ValueError(f"contact dimensions {sorted(dims)}: the native engine needs one condim for every pair")
    return ContactSlots.of(np.asarray(geom), np.asarray(addr), np.asarray(dim), int(np.shape(efc)[0]),
                           mj_model.ngeom)


def _rows(condim: int) -> int:
    """Constraint rows of a pyramidal contact of dimension ``condim``."""
    return 1 if condim == 1 else 2 * (condim - 1)


THREADS_ENV = "COMAN_NATIVE_THREADS"


def default_threads() -> int:
    """``COMAN_NATIVE_THREADS`` if set, else the CPU cores this process may run on.

    Raises:
        ValueError: a ``COMAN_NATIVE_THREADS`` that is not a whole number >= 1.
    """
    env = os.environ.get(THREADS_ENV, "").strip()
    if env:
        if not env.isdigit() or int(env) < 1:
            raise ValueError(f"{THREADS_ENV}={env!r} must be a whole number >= 1")
        return int(env)
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


class _Worker:
    """One thread's model and data."""

    def __init__(self, mj_model: mujoco.MjModel):
        self.m = mj_model.__copy__()
        self.d = mujoco.MjData(self.m)

    def set_model(self, ins: dict, i: int) -> None:
        for name in MODEL_FIELDS:
            getattr(self.m, name)[...] = ins[name][i]
        self.m.opt.gravity[:] = ins["gravity"][i]

    def run(self, rows: range, ins: dict, outs: dict, raw: "_RawContacts", per_robot_model: bool) -> None:
        m, d = self.m, self.d
        if not per_robot_model and len(rows):
            self.set_model(ins, rows[0])
        # views of the data's buffers, bound once per batch
        into = [(getattr(d, k), ins[k]) for k in ("qpos", "qvel", "ctrl", "xfrc_applied", "qacc_warmstart")]
        out = [(getattr(d, k).reshape(outs[k].shape[1:]), outs[k]) for k in OUT_FIELDS]
        cap, efc_cap = raw.geom.shape[1], raw.efc_force.shape[1]
        for i in rows:
            if per_robot_model:
                self.set_model(ins, i)
            for dst, src in into:
                dst[...] = src[i]
            mujoco.mj_step(m, d)
            for src, dst in out:
                dst[i] = src
            n = d.ncon
            if n == 0:
                continue
            if n > cap or d.nefc > efc_cap:  # decoded from a buffer of its own after the batch
                raw.spill[i] = _RawContacts.empty(1, n, d.nefc)
                _copy_contacts(raw.spill[i], 0, d)
            else:
                _copy_contacts(raw, i, d)


class _RawContacts(NamedTuple):
    """A batch's C contacts as stepped (the first ``ncon[i]`` rows of robot ``i``), before slot assignment."""

    ncon: np.ndarray  # (B,)
    geom: np.ndarray  # (B, cap, 2)
    pos: np.ndarray  # (B, cap, 3)
    frame: np.ndarray  # (B, cap, 9)
    dist: np.ndarray  # (B, cap)
    friction: np.ndarray  # (B, cap, 5)
    efc_address: np.ndarray  # (B, cap)
    efc_force: np.ndarray  # (B, efc_cap)
    spill: dict  # robot -> a one-robot _RawContacts of its own: more contacts or rows than these buffers hold

    @classmethod
    def empty(cls, batch: int, cap: int, efc_cap: int) -> "_RawContacts":
        z = lambda *shape, dtype=np.float64: np.zeros((batch, *shape), dtype)  # noqa: E731
        return cls(z(dtype=np.int64), z(cap, 2, dtype=np.int64), z(cap, 3), z(cap, 9), z(cap), z(cap, 5),
                   z(cap, dtype=np.int64), z(efc_cap), {})


def _copy_contacts(raw: _RawContacts, i: int, d: mujoco.MjData) -> None:
    """Robot ``i``'s rows of ``raw`` from the contacts and constraint forces of ``d`` (which must fit)."""
    n, c = d.ncon, d.contact
    raw.ncon[i] = n
    raw.geom[i, :n] = c.geom
    raw.pos[i, :n] = c.pos
    raw.frame[i, :n] = c.frame
    raw.dist[i, :n] = c.dist
    raw.friction[i, :n] = c.friction
    raw.efc_address[i, :n] = c.efc_address
    raw.efc_force[i, :d.nefc] = d.efc_force


def decode_contacts(raw: _RawContacts, outs: dict, slots: ContactSlots) -> None:
    """Write the batch's C contacts into MJX's slots (``outs``: ``pos``, ``frame``, ``dist``, ``friction``,
    ``efc_force``), all robots at once: contact ``j`` of a robot fills the next free slot of its geom pair, in
    C's order; a pair MJX does not collide, or more contacts of a pair than its slots, is dropped."""
    outs["dist"][...] = EMPTY_SLOT_DIST_M
    for k in ("pos", "frame", "friction", "efc_force"):
        outs[k][...] = 0.0
    for i, one in raw.spill.items():  # robots past the buffers' capacity
        _scatter(one, {k: outs[k][i:i + 1] for k in ("pos", "frame", "dist", "friction", "efc_force")}, slots)
    _scatter(raw, outs, slots)


def _scatter(raw: _RawContacts, outs: dict, slots: ContactSlots) -> None:
    cap = raw.geom.shape[1]
    live = np.arange(cap)[None, :] < raw.ncon[:, None]  # (B, cap)
    g = np.where(live[..., None], raw.geom, 0)
    pair = np.where(live, slots.pair_index[g[..., 0], g[..., 1]], -1)  # -1: a pair MJX does not collide
    earlier = (pair[:, :, None] == pair[:, None, :]) & np.tri(cap, k=-1, dtype=bool)[None]
    rank = earlier.sum(-1)  # this contact's place among its pair's, in C's order
    ok = (pair >= 0) & (rank < slots.pair_slots.shape[1])
    slot = np.where(ok, slots.pair_slots[np.maximum(pair, 0), np.minimum(rank, slots.pair_slots.shape[1] - 1)], -1)
    b, j = np.nonzero(slot >= 0)
    s = slot[b, j]
    outs["pos"][b, s] = raw.pos[b, j]
    outs["frame"][b, s] = raw.frame[b, j].reshape(-1, 3, 3)
    outs["dist"][b, s] = raw.dist[b, j]
    outs["friction"][b, s] = raw.friction[b, j]
    addr = raw.efc_address[b, j]
    keep = addr >= 0
    rows = np.arange(slots.efc_rows)
    b, s, addr = b[keep], s[keep], addr[keep]
    outs["efc_force"][b[:, None], slots.efc_address[s][:, None] + rows] = raw.efc_force[b[:, None], addr[:, None] + rows]


class NativeEngine(Engine):
    """MuJoCo C on ``n_threads`` threads (default :func:`default_threads`: every core this process may use).

    Raises:
        ValueError: a model with an elliptic friction cone (the slots decode pyramids), or ``n_threads`` not
            a whole number >= 1.
    """

    name = "native"
    differentiable = False

    def __init__(self, mj_model: mujoco.MjModel, n_threads: int | None = None):
        if mj_model.opt.cone != mujoco.mjtCone.mjCONE_PYRAMIDAL:
            raise ValueError(f"opt.cone={int(mj_model.opt.cone)}: the native engine decodes pyramidal cones only")
        n = default_threads() if n_threads is None else n_threads
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ValueError(f"n_threads={n_threads!r} must be a whole number >= 1")
        self.mj_model = mj_model.__copy__()
        self.n_threads = n
        self.slots = contact_slots(self.mj_model)
        # C's contacts (and constraint rows) a robot keeps in a batch's buffers; a robot with more is spilled
        self.contact_cap = 2 * len(self.slots.dim) + 8
        self.efc_cap = self.contact_cap * self.slots.efc_rows + 2 * self.mj_model.nv + 64
        self._workers = [_Worker(self.mj_model) for _ in range(n)]
        self._pool = concurrent.futures.ThreadPoolExecutor(n - 1) if n > 1 else None
        self._lock = threading.Lock()  # one batch at a time: the workers are shared

    def for_model(self, mj_model):
        return NativeEngine(mj_model, self.n_threads)

    def __repr__(self):
        return f"NativeEngine(n_threads={self.n_threads})"

    @functools.cached_property
    def _layout(self) -> tuple[tuple, tuple]:
        """``(inputs, outputs)``: the ``(name, shape)`` segments of a robot's packed input and output rows."""
        m, n = self.mj_model, len(self.slots.dim)
        ins = (("qpos", (m.nq,)), ("qvel", (m.nv,)), ("ctrl", (m.nu,)), ("xfrc_applied", (m.nbody, 6)),
               ("qacc_warmstart", (m.nv,)), *((f, getattr(m, f).shape) for f in MODEL_FIELDS), ("gravity", (3,)))
        outs = (("qpos", (m.nq,)), ("qvel", (m.nv,)), ("qacc_warmstart", (m.nv,)), ("xpos", (m.nbody, 3)),
                ("xquat", (m.nbody, 4)), ("xmat", (m.nbody, 3, 3)), ("xipos", (m.nbody, 3)),
                ("subtree_com", (m.nbody, 3)), ("site_xpos", (m.nsite, 3)), ("site_xmat", (m.nsite, 3, 3)),
                ("pos", (n, 3)), ("frame", (n, 3, 3)), ("dist", (n,)), ("friction", (n, 5)),
                ("efc_force", (self.slots.nefc,)))
        return ins, outs

    def _host_step(self, packed):
        """The batch's packed rows ``(..., n_in)`` -> ``(..., n_out)``, stepped by the workers."""
        x = np.asarray(packed)
        batch, dtype = x.shape[:-1], x.dtype
        size = math.prod(batch)
        x = x.reshape(size, -1).astype(np.float64)
        ins_layout, outs_layout = self._layout
        ins, lo = {}, 0
        for name, shape in ins_layout:
            hi = lo + math.prod(shape)
            ins[name] = x[:, lo:hi].reshape((size,) + shape)
            lo = hi
        model_rows = x[:, _span(ins_layout, MODEL_FIELDS[0], "gravity")]
        per_robot_model = size > 1 and not bool(np.all(model_rows == model_rows[:1]))
        y = np.empty((size, sum(math.prod(s) for _, s in outs_layout)), np.float64)
        outs, lo = {}, 0
        for name, shape in outs_layout:
            hi = lo + math.prod(shape)
            outs[name] = y[:, lo:hi].reshape((size,) + shape)
            lo = hi
        raw = _RawContacts.empty(size, self.contact_cap, self.efc_cap)
        with self._lock:
            if self._pool is None or size < 2:
                self._workers[0].run(range(size), ins, outs, raw, per_robot_model)
            else:
                parts = [range(size * k // self.n_threads, size * (k + 1) // self.n_threads)
                         for k in range(self.n_threads)]
                jobs = [self._pool.submit(w.run, r, ins, outs, raw, per_robot_model)
                        for w, r in zip(self._workers[1:], parts[1:]) if len(r)]
                self._workers[0].run(parts[0], ins, outs, raw, per_robot_model)  # this thread takes a part
                for j in jobs:
                    j.result()
        decode_contacts(raw, outs, self.slots)
        return y.astype(dtype).reshape(batch + (y.shape[1],))

    def step(self, model, data):
        f = data.qpos.dtype
        args = (data.qpos, data.qvel, data.ctrl, data.xfrc_applied, data.qacc_warmstart,
                *(getattr(model, k) for k in MODEL_FIELDS), model.opt.gravity)
        flat = _native_step(self, jnp.concatenate([jnp.ravel(a).astype(f) for a in args]))
        out, lo = {}, 0
        for name, shape in self._layout[1]:
            hi = lo + math.prod(shape)
            out[name] = flat[lo:hi].reshape(shape)
            lo = hi
        c = data._impl.contact
        geom = jnp.asarray(self.slots.geom, c.geom.dtype)
        contact = c.replace(geom=geom, geom1=geom[:, 0], geom2=geom[:, 1], **{k: out[k] for k in CONTACT_FIELDS})
        data = data.replace(time=data.time + model.opt.timestep, **{k: out[k] for k in OUT_FIELDS})
        return data.tree_replace({"_impl.contact": contact, "_impl.efc_force": out["efc_force"]})


def _span(layout: tuple, first: str, last: str) -> slice:
    """The columns of the segments ``first`` to ``last`` (inclusive) of a packed row."""
    lo = start = stop = 0
    for name, shape in layout:
        if name == first:
            start = lo
        lo += math.prod(shape)
        if name == last:
            stop = lo
    return slice(start, stop)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _native_step(engine: NativeEngine, packed):
    n_out = sum(math.prod(s) for _, s in engine._layout[1])
    return jax.pure_callback(engine._host_step, jax.ShapeDtypeStruct((n_out,), packed.dtype), packed,
                             vmap_method="broadcast_all")


@_native_step.defjvp
def _no_derivative(engine, primals, tangents):
    raise ValueError("the native engine (MuJoCo C) has no derivatives: differentiate on the 'mjx' engine")
