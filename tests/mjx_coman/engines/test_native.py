"""mjx_coman.engines.native: MuJoCo C behind the engine protocol, checked against MuJoCo C itself, against
MJX on the contract batch of every position-controlled controller, and for independence of threads and
neighbours in a batch."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from mjx_coman import env as env_mod
from mjx_coman.engines import ENGINES, make_engine
from mjx_coman.engines.native import MODEL_FIELDS, NativeEngine


@pytest.fixture(scope="module")
def params(env_params):
    return env_mod.use_engine(env_params, "native", n_threads=2)


@pytest.fixture(scope="module")
def jit_step(params):
    return jax.jit(lambda d: params.engine.step(params.model, d))


@pytest.fixture(scope="module")
def settled(params, reset_state, standing_q):
    """The crouched robot after 0.3 s of standing under its position loops (environment ticks on the engine)."""
    cmd = env_mod.make_command(standing_q)
    run = jax.jit(lambda s: jax.lax.scan(lambda s, _: (env_mod.step(params, s, cmd), None), s, None, length=150)[0])
    return run(reset_state).data


def _c_data(params, d) -> tuple[mujoco.MjModel, mujoco.MjData]:
    m = params.engine.mj_model
    c = mujoco.MjData(m)
    c.qpos[:], c.qvel[:], c.qacc_warmstart[:] = (np.asarray(x, np.float64) for x in (d.qpos, d.qvel, d.qacc_warmstart))
    c.ctrl[:], c.xfrc_applied[:] = np.asarray(d.ctrl), np.asarray(d.xfrc_applied)
    return m, c


def test_bad_engine_choices_name_the_value():
    with pytest.raises(ValueError, match="'bullet'.*mjx, native"):
        make_engine("bullet")
    with pytest.raises(ValueError, match="needs the MjModel"):
        make_engine("native")
    from mjx_coman import load_model

    with pytest.raises(ValueError, match="n_threads=0"):
        NativeEngine(load_model(), n_threads=0)
    assert ENGINES == ("mjx", "native")


def test_the_default_thread_count_is_the_cores_or_the_environments(monkeypatch):
    from mjx_coman.engines import native

    monkeypatch.delenv(native.THREADS_ENV, raising=False)
    cores = native.default_threads()
    assert cores >= 1
    monkeypatch.setenv(native.THREADS_ENV, "3")
    assert native.default_threads() == 3
    monkeypatch.setenv(native.THREADS_ENV, "zero")
    with pytest.raises(ValueError, match="COMAN_NATIVE_THREADS='zero'"):
        native.default_threads()


def test_use_engine_refuses_another_scenes_model(params):
    from mjx_coman.scenarios.terrain import scene_model

    with pytest.raises(ValueError, match="not the model of these params.*ngeom"):
        env_mod.use_engine(params, "native", mj_model=scene_model("stairs:5"))
    other = mujoco.MjModel.from_xml_path(str(__import__("mjx_coman").model_path()))
    other.opt.timestep = 0.002
    with pytest.raises(ValueError, match="timestep 0.002"):
        env_mod.use_engine(params, "native", mj_model=other)


def test_a_step_is_mj_step_and_the_contacts_decode_to_mujocos_forces(params, jit_step, settled):
    """One engine step from the settled state equals ``mj_step`` run directly, and the feet's forces decoded
    from the MJX contact slots (:func:`mjx_coman.sensors.foot_wrenches`) equal MuJoCo's ``mj_contactForce``
    summed per foot, and carry the robot's weight."""
    from mjx_coman.sensors import foot_wrenches

    m, c = _c_data(params, settled)
    mujoco.mj_step(m, c)
    d = jit_step(settled)
    np.testing.assert_allclose(np.asarray(d.qpos), c.qpos, atol=1e-5)
    np.testing.assert_allclose(np.asarray(d.xpos), c.xpos, atol=1e-5)  # the state the step started from
    assert float(d.time) == pytest.approx(float(settled.time) + 0.001)
    force = np.zeros(3)
    for j in range(c.ncon):  # world-frame force on the robot (geom2 of every floor pair)
        f6 = np.zeros(6)
        mujoco.mj_contactForce(m, c, j, f6)
        force += c.contact.frame[j].reshape(3, 3).T @ f6[:3]
    _, _, normal = foot_wrenches(d)
    assert float(jnp.sum(normal)) == pytest.approx(force[2], rel=1e-3)
    weight = float(np.sum(m.body_mass)) * 9.81
    assert 0.8 * weight < force[2] < 1.2 * weight


def test_contacts_fill_their_pairs_slots_in_c_order_for_the_whole_batch_at_once():
    """The batched decode: a pair's contacts take its slots in C's order, a contact past its pair's slots or of
    a pair MJX does not collide is dropped, a contact without constraint rows leaves its slot's forces zero, a
    robot without contacts has empty slots, and a robot spilled past the buffers decodes the same."""
    from mjx_coman.engines.native import EMPTY_SLOT_DIST_M, ContactSlots, _RawContacts, decode_contacts

    slots = ContactSlots.of(np.asarray([[0, 1], [0, 1], [0, 2]]), np.asarray([10, 14, 18]), np.full(3, 3), 22, 3)
    geom = np.asarray([[0, 2], [0, 1], [0, 1], [1, 2], [0, 1]])  # C's order
    addr = np.asarray([5, -1, 9, 13, 17])
    one = dict(geom=geom, pos=np.arange(15.0).reshape(5, 3), frame=np.arange(45.0).reshape(5, 9) + 100,
               dist=-np.arange(1.0, 6.0) / 1000, friction=np.arange(25.0).reshape(5, 5) + 200, efc_address=addr,
               efc_force=np.arange(30.0) + 1000)
    raw, alone = _RawContacts.empty(3, 5, 30), _RawContacts.empty(1, 5, 30)
    for buf in (raw, alone):
        buf.ncon[0] = 5
        for k, v in one.items():
            getattr(buf, k)[0, :len(v)] = v
    raw.spill[2] = alone
    outs = dict(pos=np.full((3, 3, 3), 9.0), frame=np.full((3, 3, 3, 3), 9.0), dist=np.zeros((3, 3)),
                friction=np.full((3, 3, 5), 9.0), efc_force=np.full((3, 22), 9.0))
    decode_contacts(raw, outs, slots)
    for b in (0, 2):
        np.testing.assert_array_equal(outs["pos"][b], one["pos"][[1, 2, 0]])
        np.testing.assert_array_equal(outs["frame"][b], one["frame"][[1, 2, 0]].reshape(3, 3, 3))
        np.testing.assert_array_equal(outs["dist"][b], one["dist"][[1, 2, 0]])
        np.testing.assert_array_equal(outs["friction"][b], one["friction"][[1, 2, 0]])
        want = np.zeros(22)
        want[14:18] = one["efc_force"][9:13]  # slot 1 <- contact 2
        want[18:22] = one["efc_force"][5:9]  # slot 2 <- contact 0; slot 0's contact has no rows
        np.testing.assert_array_equal(outs["efc_force"][b], want)
    np.testing.assert_array_equal(outs["dist"][1], EMPTY_SLOT_DIST_M)
    for k in ("pos", "frame", "friction", "efc_force"):
        assert not np.any(outs[k][1]), k


def test_a_robot_past_the_contact_buffers_steps_the_same(params, settled):
    """With buffers of one contact, every standing robot (4 or more foot contacts) is spilled and decoded from
    a buffer of its own: the packed outputs equal those of the normal path bit for bit."""
    engine = NativeEngine(params.engine.mj_model, n_threads=1)
    m = engine.mj_model
    c = mujoco.MjData(m)
    c.qpos[:], c.qvel[:] = np.asarray(settled.qpos, np.float64), np.asarray(settled.qvel, np.float64)
    mujoco.mj_step(m, c)
    assert c.ncon >= 2
    row = np.concatenate([np.ravel(m.opt.gravity if name == "gravity" else getattr(m if name in MODEL_FIELDS else c,
                                                                                  name))
                          for name, _ in engine._layout[0]])
    x = np.stack([row, row])
    normal = engine._host_step(x)
    engine.contact_cap = 1
    spilled = engine._host_step(x)
    np.testing.assert_array_equal(spilled, normal)
    assert np.any(normal[:, -engine.slots.nefc:])  # the contacts carry force


def test_the_batch_steps_each_robot_as_alone_on_any_thread_count(params, settled):
    """Three robots with their own velocities and body masses (a per-rollout model field) in one call on 2
    threads give bit for bit what each gives alone on 1 thread."""
    one = env_mod.use_engine(params, "native", n_threads=1)
    scale = jnp.asarray([1.0, 1.1, 0.9])
    data = jax.tree_util.tree_map(lambda x: jnp.stack([x] * 3), settled)
    data = data.replace(qvel=data.qvel.at[:, 0].add(jnp.asarray([0.0, 0.2, -0.3])))
    models = params.model.replace(body_mass=params.model.body_mass[None] * scale[:, None])
    axes = jax.tree_util.tree_map(lambda _: None, params.model).replace(body_mass=0)
    batch = jax.jit(jax.vmap(params.engine.step, in_axes=(axes, 0)))(models, data)
    step = jax.jit(one.engine.step)
    for i in range(3):
        alone = step(params.model.replace(body_mass=models.body_mass[i]),
                                         jax.tree_util.tree_map(lambda x: x[i], data))
        for f in ("qpos", "qvel", "xpos", "subtree_com"):
            np.testing.assert_array_equal(np.asarray(getattr(batch, f)[i]), np.asarray(getattr(alone, f)), err_msg=f)
    assert not np.allclose(np.asarray(batch.qvel[1]), np.asarray(batch.qvel[2]))
    assert "body_mass" in MODEL_FIELDS


def test_a_derivative_through_the_native_step_is_refused(params, settled):
    with pytest.raises(ValueError, match="no derivatives"):
        jax.jvp(lambda q: params.engine.step(params.model, settled.replace(qpos=q)).qpos,
                (settled.qpos,), (jnp.ones_like(settled.qpos),))


def _row_key(row):
    name, push, seed, delta = row
    return name, seed, None if push is None else float(np.max(np.abs(np.asarray(push.force_n)))), delta


def test_every_position_controlled_controller_walks_the_same_on_both_engines(shared_walks, native_shared_walks):
    """The contract batch of the position-controlled families (unpushed walks, a 5 N s push, an absurd push,
    every variant) on MuJoCo C: the same falls, at about the same time, and the same pelvis trajectory as on
    MJX (``shared_walks``) to within a few millimetres over 2.4 s."""
    rows, res = native_shared_walks[:2]
    ref_rows, ref = shared_walks[:2]
    ref_index = {_row_key(r): i for i, r in reversed(list(enumerate(ref_rows)))}
    checked = 0
    for i, row in enumerate(rows):
        j = ref_index[_row_key(row)]
        assert bool(res.fell[i]) == bool(ref.fell[j]), row
        up = np.asarray(res.time_s[i]) < min(float(res.fall_time_s[i]), float(ref.fall_time_s[j]))
        d = np.linalg.norm(np.asarray(res.saved["pelvis_m"][i]) - np.asarray(ref.saved["pelvis_m"][j]), axis=-1)[up]
        print(row[0], row[2], bool(res.fell[i]), float(res.fall_time_s[i]), float(ref.fall_time_s[j]), d.max())
        assert d.max() < 0.005, (row, d.max())
        if res.fell[i]:
            assert abs(float(res.fall_time_s[i]) - float(ref.fall_time_s[j])) < 0.05, row
        checked += 1
    assert checked == len(rows) and any(res.fell) and not all(res.fell)
