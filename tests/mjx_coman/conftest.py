"""Shared, session-scoped fixtures: one compiled reset and tick chunk, and one compiled walk of every controller."""

from typing import NamedTuple

import jax
import numpy as np
import pytest

from mjx_coman import experiments
from mjx_coman.env import make_env_params, standing_posture


@pytest.fixture(scope="session")
def env_params():
    return make_env_params()


@pytest.fixture(scope="session")
def standing_q():
    return standing_posture()[0]


@pytest.fixture(scope="session")
def reset_state(env_params):
    return experiments._reset(jax.random.PRNGKey(0), env_params)


@pytest.fixture(scope="session")
def stand_run(env_params, reset_state, standing_q):
    """One second of standing under position control (500 ticks), every tick recorded."""
    n = 500
    final, rec = experiments.run(env_params, reset_state, np.broadcast_to(standing_q, (n, len(standing_q))),
                                 np.zeros((n, 3)))
    return final, rec


# --- shared walks: one compiled, vmapped, forward-differentiated walk of every controller family ----------
#
# Every registered controller name runs in one batch: the families are bundled into one controller
# (mjx_coman.controllers.bundle: a switch on an index), and the variants of a family are configurations of
# its member. One call gives the contract test its unpushed walks and its gradient checks (rows perturbed
# by +-h for central differences) and the rollout and ground-truth tests their pushed walks, so the whole
# suite compiles one walk for all of them (the physics, most of the compilation, once).

WALK_S = 2.4  # a start-up phase and five steps of the time-projection gait
WALK_ROWS = 16
TORQUE_WALK_ROWS = 2  # per family at least: its unpushed walk and a variant's (more rows if it has more variants)
TORQUE_GRAD_ROWS = 4  # the gradient check's three rows (slow: a second, forward-differentiated compilation)
TORQUE_WALK_S = 1.0  # a QP a tick (with its tangent): the torque batch walks shorter
GRAD_WINDOW_S = 0.3  # the cost of the gradient check: the controller's own start, before any step
PUSH_START_S = (1 + 1 + 0.375) * 0.4  # walking step 1 of the time-projection gait, 3/8 through
RECORD_EVERY = 10


def walk_record(state):
    """What the shared walks save every 10 ticks (ground truth, the readings, the command and the whole
    telemetry)."""
    from mjx_coman import ground_truth as gt
    from mjx_coman.sensors import model_ids

    d = state.env.data
    return dict(pelvis_m=gt.pelvis_m(d), com_m=gt.com_m(d), feet_m=gt.foot_points_world(d),
                pelvis_quat=d.xquat[model_ids()["pelvis_body"]], telemetry=state.telemetry,
                readings=state.env.readings, command=state.command)


def probe_setting(ctrl) -> str:
    """The tunable the gradient check differentiates: the first scalar one with a nonzero default."""
    for s in ctrl.settings:
        if s.tunable and isinstance(s.default, (int, float)) and not isinstance(s.default, bool) and s.default:
            return s.name
    raise AssertionError(f"{ctrl.name} declares no scalar tunable with a nonzero default")


def grad_cost(saved):
    """Mean horizontal CoM coordinate sum over the first GRAD_WINDOW_S of each walk (smooth, feet down)."""
    n = int(round(GRAD_WINDOW_S / (0.002 * RECORD_EVERY)))
    return saved["com_m"][:, :n, :2].sum(-1).mean(-1)


def torque_controlled(name) -> bool:
    """The controller commands torques (its plant is a torque plant): it runs in the torque batch."""
    from mjx_coman import controllers

    ctrl = controllers.get(name)
    return ctrl.gait(controllers.default_config(name)).plant != "position"


def _families(torque: bool = False):
    """``[(representative name, [its variant names])]`` of the registry, one per family, of one batch."""
    from mjx_coman import controllers

    out = []
    for n in controllers.names():
        core = controllers.get(n).core()
        for rep, members in out:
            if controllers.get(rep).core() == core:
                members.append(n)
                break
        else:
            out.append((n, [n]))
    return [(rep, ms) for rep, ms in out if torque_controlled(rep) == torque]


def _rows(fams, pushed: bool = True, gradient: bool = True):
    """Per family: the probe, its step h, and rows ``(name, push, seed, delta)``; all rows in one list
    (``gradient=False``: without the +-h rows)."""
    from mjx_coman import controllers, rollout as ro

    back = ro.make_push(PUSH_START_S, 0.1, impulse_ns=5.0, direction_rad=np.pi)
    absurd = ro.make_push(1.0, 0.05, force_n=[3e6, 0.0, 1e6])
    rows, probes = [], {}
    for rep, members in fams:
        probe = probe_setting(controllers.get(rep))
        h = 0.05 * abs(float(controllers.get(rep).defaults()[probe]))
        probes[rep] = (probe, h)
        rows += [(rep, None, 0, 0.0)] + ([(rep, None, 0, h), (rep, None, 0, -h)] if gradient else [])
        rows += [(rep, back, 7, 0.0), (rep, absurd, 7, 0.0)] if pushed else []
        rows += [(m, None, 1, 0.0) for m in members[1:]]
        rows += [(m, back, 7, 0.0) for m in members[1:] if m == "open-loop"]  # the push it cannot take
    return rows, probes


@pytest.fixture(scope="session")
def walking_env():
    from mjx_coman.rollout import walking_env_params

    return walking_env_params()


def _batch(fams, n_rows, seconds, shared_env=None, pushed=True, gradient=True):
    """``(rows, results, cost, dcost, probes)`` of one bundled batch (compiled and run once).

    ``gradient=False``: no +-h rows and no forward-mode derivative (``dcost`` is ``None``).

    ``shared_env``: every row's environment; ``None``: each row gets its controller's plant
    (:func:`mjx_coman.rollout.plant_env_params`), vmapped over the rows.
    """
    from mjx_coman import controllers, env as env_mod, rollout as ro
    from mjx_coman.controllers.bundle import bundle, bundle_config

    reps = [rep for rep, _ in fams]
    member_of = {m: i for i, (_, ms) in enumerate(fams) for m in ms}
    both = bundle([controllers.get(r) for r in reps]) if len(reps) > 1 else None
    rows, probes = _rows(fams, pushed, gradient)
    assert len(rows) <= n_rows, len(rows)
    rows = rows + [rows[0]] * (n_rows - len(rows))  # one batch size
    defaults = [controllers.default_config(r) for r in reps]
    configs, tangents = [], []
    for name, _, _, delta in rows:
        i = member_of[name]
        probe = probes[reps[i]][0]
        own = controllers.default_config(name)
        if delta:
            own = own.replace(**{probe: getattr(own, probe) + delta})
        if both is None:
            if jax.tree_util.tree_structure(own) != jax.tree_util.tree_structure(defaults[i]):
                # a variant on another plant: the plant is its row's environment, the static field only names it
                own = own.replace(plant=defaults[i].plant)
            configs.append(own)
            zero = jax.tree_util.tree_map(np.zeros_like, own)
            tangents.append(zero.replace(**{probe: np.ones_like(getattr(zero, probe))}))
            continue
        cfgs = [own if j == i else defaults[j] for j in range(len(reps))]
        configs.append(bundle_config(i, cfgs))
        zero = jax.tree_util.tree_map(np.zeros_like, bundle_config(i, cfgs))
        tangents.append(zero.replace(configs=tuple(
            c.replace(**{probes[r][0]: np.ones_like(getattr(c, probes[r][0]))}) for c, r in zip(zero.configs, reps))))
    stack = lambda xs: jax.tree_util.tree_map(lambda *a: np.stack([np.asarray(x) for x in a]), *xs)  # noqa: E731
    pushes = stack([p if p is not None else ro.no_push() for _, p, _, _ in rows])
    keys = np.stack([np.asarray(jax.random.PRNGKey(s)) for _, _, s, _ in rows])
    spec, save, joy = ro.WalkSpec(seconds=seconds), ro.SaveAt(walk_record, every=RECORD_EVERY), controllers.joystick()
    core = (both or controllers.get(reps[0])).core()
    if shared_env is not None:
        envs, env_axes = shared_env, None
    else:
        plant = lambda n: controllers.get(n).gait(controllers.default_config(n)).plant  # noqa: E731
        envs = stack([ro.plant_env_params(plant(n)).actuator for n, _, _, _ in rows])
        base = ro.plant_env_params(plant(rows[0][0]))
        envs = base.__class__(model=base.model, actuator=envs, sensor=jax.tree_util.tree_map(
            lambda x: np.stack([np.asarray(x)] * n_rows), base.sensor), n_substeps=base.n_substeps)
        env_axes = env_mod.batch_axes(envs)

    def batch(cfg):
        r = jax.vmap(lambda c, e, p, k: ro.walk(core, c, e, p, k, spec, joy, save),
                     in_axes=(0, env_axes, 0, 0))(cfg, envs, pushes, keys)
        return r, grad_cost(r.saved)

    if not gradient:
        res, cost = jax.jit(batch)(stack(configs))
        return rows, jax.tree_util.tree_map(np.asarray, res), np.asarray(cost), None, probes
    tangent = stack(tangents)
    if both is not None:
        tangent = tangent.replace(index=np.zeros(n_rows, jax.dtypes.float0))
    (res, cost), (_, dcost) = jax.jit(lambda c, t: jax.jvp(batch, (c,), (t,)))(stack(configs), tangent)
    return rows, jax.tree_util.tree_map(np.asarray, res), np.asarray(cost), np.asarray(dcost), probes


@pytest.fixture(scope="session")
def shared_walks(walking_env):
    """The batch of every position-controlled family (one compilation)."""
    return _batch(_families(), WALK_ROWS, WALK_S, walking_env)


@pytest.fixture(scope="session")
def native_shared_walks(walking_env):
    """The batch of ``shared_walks`` without its gradient rows, on the native engine (MuJoCo C)."""
    from mjx_coman.env import use_engine

    return _batch(_families(), WALK_ROWS, WALK_S, use_engine(walking_env, "native"), gradient=False)


def family_of(name) -> str:
    """The first registered name of ``name``'s family (its representative)."""
    from mjx_coman import controllers

    core = controllers.get(name).core()
    return next(n for n in controllers.names() if controllers.get(n).core() == core)


@pytest.fixture(scope="session")
def torque_walks():
    """``torque_walks(rep, gradient=False)``: the batch of one torque-controlled family, each row on its own
    plant (one compilation per family, not a bundle: every row would run every family's QP); ``gradient``:
    the gradient check's batch (forward-differentiated: slow tests only)."""
    cache = {}

    def get(rep, gradient=False):
        if (rep, gradient) not in cache:
            fams = [f for f in _families(torque=True) if f[0] == rep]
            n_rows = max(TORQUE_GRAD_ROWS if gradient else TORQUE_WALK_ROWS, len(_rows(fams, False, gradient)[0]))
            cache[rep, gradient] = _batch(fams, n_rows, TORQUE_WALK_S,
                                          pushed=False, gradient=gradient)
        return cache[rep, gradient]

    return get


class FamilyBatch(NamedTuple):
    """The shared batch seen from one family: ``rows[sel]`` are its unperturbed, +h and -h walks of the
    gradient check; ``member`` indexes its part of the bundle (``telemetry.extra[member]``)."""

    rows: list
    res: object
    cost: np.ndarray
    dcost: np.ndarray
    probe: str
    h: float
    sel: tuple
    member: int


@pytest.fixture(scope="session")
def family_walks(request):
    """``family_walks(name, gradient=False) -> FamilyBatch`` of the shared batch (position or torque) of
    ``name``'s family (``gradient``: with the gradient check's rows, a second batch for a torque family)."""
    from mjx_coman import controllers

    def get(name, gradient=False):
        if torque_controlled(name):
            rows, res, cost, dcost, probes = request.getfixturevalue("torque_walks")(family_of(name), gradient)
        else:
            rows, res, cost, dcost, probes = request.getfixturevalue("shared_walks")
        core = controllers.get(name).core()
        member, rep = next((j, r) for j, r in enumerate(probes) if controllers.get(r).core() == core)
        i0 = next(i for i, (n, p, _, d) in enumerate(rows) if n == rep and p is None and d == 0.0)
        probe, h = probes[rep]
        return FamilyBatch(rows, res, cost, dcost, probe, h, (i0, i0 + 1, i0 + 2), member)

    return get
