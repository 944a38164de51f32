"""Whole-body dynamics terms (mjx_coman.dynamics) against MuJoCo's C functions and finite differences, float64.

One jitted ``terms`` (real model) and one jitted, vmapped bundle of the public
functions (a model with joint springs and dampers added) serve every test.
"""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

from mjx_coman import dynamics as dyn
from mjx_coman import load_model

N_STATES = 4
C_RTOL = 1e-8  # against MuJoCo's C functions: |a - b| <= C_RTOL * max(1, max |b|)
FD_STEP = 1e-5  # central differences along q(t) = mj_integratePos(q, qvel, t)
# FD error: truncation ~ h^2 |d3/dt3 (J qvel)| (measured ~3e-9 at 1e-5, scaling as h^2 from 1e-3 down)
# plus rounding ~ 1e-16 |J qvel| / h ~ 1e-10; a wrong term gives O(1) errors.
FD_RTOL = 1e-7


@pytest.fixture(scope="module", autouse=True)
def x64():
    """Run the whole module in float64."""
    with jax.enable_x64(True):
        yield


def _close(actual, expected, rtol, what):
    actual, expected = np.asarray(actual), np.asarray(expected)
    assert actual.shape == expected.shape, (what, actual.shape, expected.shape)
    err, scale = np.max(np.abs(actual - expected)), max(1.0, np.max(np.abs(expected)))
    assert err <= rtol * scale, f"{what}: max error {err:.3g} > {rtol:g} * {scale:.3g}"


def _random_state(m, rng):
    """Joint angles within their limits, random base position and unit quaternion, random velocities."""
    q = m.qpos0.copy()
    q[:3] = rng.normal(size=3)
    quat = rng.normal(size=4)
    q[3:7] = quat / np.linalg.norm(quat)
    q[7:] = rng.uniform(m.jnt_range[1:, 0], m.jnt_range[1:, 1])
    v = np.r_[rng.normal(0.0, 0.5, 3), rng.normal(0.0, 1.0, 3), rng.normal(0.0, 2.0, m.nv - 6)]
    return q, v


def _c_data(m, q, v):
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:] = q, v
    mujoco.mj_forward(m, d)
    mujoco.mj_subtreeVel(m, d)
    return d


def _c_jac(m, d, body, point):
    jp, jr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    mujoco.mj_jac(m, d, jp, jr, point, body)
    return np.r_[jp, jr]


def _c_jac_dot_qvel(m, d, body, point):
    jp, jr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    mujoco.mj_jacDot(m, d, jp, jr, point, body)
    return np.r_[jp, jr] @ d.qvel


def _site(m, name):
    return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, name)


@pytest.fixture(scope="module")
def model():
    m = load_model()
    mx = mjx.put_model(m)
    return m, mx, mjx.make_data(mx)


@pytest.fixture(scope="module")
def fns():
    """Jitted ``prepare(model, data at (q, v))`` and ``terms(model, data)``, the model an argument.

    Compiled once for the module: COMAN and COMAN with springs and dampers share
    them (they differ in array fields only), and ``terms`` does not recompile
    the kinematics.
    """
    prep = jax.jit(lambda model, d0, q, v: dyn.prepare(model, d0.replace(qpos=q, qvel=v)))
    return prep, jax.jit(dyn.terms)


@pytest.fixture(scope="module")
def terms_fn(model, fns):
    """``terms`` at ``(qpos, qvel)``."""
    _, mx, d0 = model
    prep, terms = fns
    return lambda q, v: terms(mx, prep(mx, d0, q, v))


@pytest.fixture(scope="module")
def states(model, terms_fn):
    """``[(q, v, terms, C data)]`` at random states."""
    m = model[0]
    rng = np.random.default_rng(20240601)
    out = []
    for _ in range(N_STATES):
        q, v = _random_state(m, rng)
        out.append((q, v, jax.tree_util.tree_map(np.asarray, terms_fn(q, v)), _c_data(m, q, v)))
    return out


def test_mass_bias_passive_match_mujoco(model, states):
    m = model[0]
    for _, _, w, d in states:
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, full)
        _close(w.mass, full, C_RTOL, "mass matrix vs mj_fullM")
        np.testing.assert_array_equal(w.mass, w.mass.T)
        _close(w.bias, d.qfrc_bias, C_RTOL, "bias vs qfrc_bias")
        _close(w.passive, d.qfrc_passive, C_RTOL, "passive vs qfrc_passive")


def test_contact_points_and_jacobians_match_mujoco(model, states):
    m = model[0]
    info = dyn.foot_contact_points_local(m)
    for _, _, w, d in states:
        for f in range(2):
            for k in range(4):
                g, b = info["geom_id"][f, k], info["body_id"][f]
                lowest = d.geom_xpos[g] - m.geom_size[g, 0] * d.xmat[b].reshape(3, 3)[:, 2]
                _close(w.contact_pos[f, k], lowest, C_RTOL, "contact point vs geom_xpos - r z")
                _close(w.contact_jac[f, k], _c_jac(m, d, b, lowest)[:3], C_RTOL, "contact Jacobian vs mj_jac")
                _close(w.contact_bias_acc[f, k], _c_jac_dot_qvel(m, d, b, lowest)[:3], C_RTOL,
                       "contact Jdot qvel vs mj_jacDot")


def test_site_frames_match_mujoco(model, states):
    m = model[0]
    fields = [(s, lambda w, i=i: (w.sole_jac[i], w.sole_bias_acc[i], w.sole_pos[i], w.sole_rot[i]))
              for i, s in enumerate(dyn.SOLE_SITES)]
    fields += [(dyn.TORSO_SITE, lambda w: (w.torso_jac, w.torso_bias_acc, w.torso_pos, w.torso_rot)),
               (dyn.PELVIS_SITE, lambda w: (w.pelvis_jac, w.pelvis_bias_acc, w.pelvis_pos, w.pelvis_rot))]
    for _, _, w, d in states:
        for name, get in fields:
            s = _site(m, name)
            jac, acc, pos, rot = get(w)
            jp, jr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
            mujoco.mj_jacSite(m, d, jp, jr, s)
            _close(jac, np.r_[jp, jr], C_RTOL, f"{name} Jacobian vs mj_jacSite")
            _close(acc, _c_jac_dot_qvel(m, d, m.site_bodyid[s], d.site_xpos[s]), C_RTOL, f"{name} vs mj_jacDot")
            _close(pos, d.site_xpos[s], C_RTOL, f"{name} position")
            _close(rot, d.site_xmat[s].reshape(3, 3), C_RTOL, f"{name} orientation")


def test_com_and_momentum_match_mujoco(model, states):
    m = model[0]
    mass = m.body_subtreemass[1]
    for _, v, w, d in states:
        assert w.total_mass_kg == pytest.approx(mass, rel=1e-12)
        _close(w.com, d.subtree_com[1], C_RTOL, "CoM vs subtree_com[1]")
        jac = np.zeros((3, m.nv))
        mujoco.mj_jacSubtreeCom(m, d, jac, 1)
        _close(w.com_jac, jac, C_RTOL, "CoM Jacobian vs mj_jacSubtreeCom")
        _close(w.com_vel, d.subtree_linvel[1], C_RTOL, "CoM velocity vs subtree_linvel[1]")
        _close(w.cmm[:3] @ v, mass * d.subtree_linvel[1], C_RTOL, "linear momentum vs m subtree_linvel")
        _close(w.cmm[3:] @ v, d.subtree_angmom[1], C_RTOL, "angular momentum vs subtree_angmom")
        _close(w.momentum, w.cmm @ v, 1e-12, "momentum = cmm qvel")
        # Newton: with qacc = 0 the momentum rate's linear part is m times the CoM bias acceleration.
        _close(w.cmm_bias[:3], mass * w.com_bias_acc, 1e-12, "linear momentum rate")


def test_bias_accelerations_match_finite_differences(model, terms_fn, states):
    """``Jdot qvel`` = d/dt [J(q(t)) qvel] along q(t) = mj_integratePos(q, qvel, t) (qacc = 0)."""
    m = model[0]
    pairs = [("contact_jac", "contact_bias_acc"), ("sole_jac", "sole_bias_acc"), ("torso_jac", "torso_bias_acc"),
             ("pelvis_jac", "pelvis_bias_acc"), ("com_jac", "com_bias_acc"), ("cmm", "cmm_bias")]
    for q, v, w, _ in states:
        ends = []
        for t in (FD_STEP, -FD_STEP):
            qt = q.copy()
            mujoco.mj_integratePos(m, qt, v, t)
            ends.append(terms_fn(qt, v))
        for jac, acc in pairs:
            vel_p, vel_m = (np.asarray(getattr(e, jac)) @ v for e in ends)
            _close(getattr(w, acc), (vel_p - vel_m) / (2 * FD_STEP), FD_RTOL, f"{acc} vs d/dt ({jac} qvel)")


def test_foot_contact_points_local(model):
    m = model[0]
    info = dyn.foot_contact_points_local()
    names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) for b in info["body_id"]]
    assert names == ["RFoot", "LFoot"]
    pts = info["points_local_m"]
    assert pts.shape == (2, 4, 3)
    np.testing.assert_allclose(pts[..., 2], -0.09, atol=1e-12)  # in the sole plane
    np.testing.assert_allclose(pts[:, :, 0], [[0.12, 0.12, -0.06, -0.06]] * 2, atol=1e-12)
    np.testing.assert_allclose(pts[:, :, 1], [[0.04, -0.04, 0.04, -0.04]] * 2, atol=1e-12)


@pytest.fixture(scope="module")
def sprung():
    """COMAN with joint springs and dampers added (so that the passive forces are not zero)."""
    m = load_model()
    rng = np.random.default_rng(7)
    m.dof_damping[6:] = rng.uniform(0.1, 2.0, m.nv - 6)
    m.jnt_stiffness[1:] = rng.uniform(1.0, 50.0, m.njnt - 1)
    return m, mjx.put_model(m)


def test_public_functions_vmapped_match_mujoco(sprung, fns):
    """Every public function, vmapped over a batch of 2 states with traced body and site ids."""
    m, mx = sprung
    d0 = mjx.make_data(mx)
    prep = fns[0]
    rng = np.random.default_rng(11)
    qs, vs = map(np.stack, zip(*[_random_state(m, rng) for _ in range(2)]))
    bodies = np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n) for n in ("RFoot", "DWYTorso")])
    sites = np.array([_site(m, "l_sole"), _site(m, "imu")])
    local = rng.normal(0.0, 0.1, (2, 3))

    def public(mx, d, body, site, p_local):
        p_world = d.xpos[body] + d.xmat[body] @ p_local
        return dict(
            mass=dyn.mass_matrix(mx, d), bias=dyn.bias_forces(mx, d), passive=dyn.passive_forces(mx, d),
            point_jac=dyn.point_jacobian(mx, d, body, p_world), frame_jac=dyn.frame_jacobian(mx, d, body, p_world),
            site_jac=dyn.site_jacobian(mx, d, site), point_acc=dyn.point_bias_acc(mx, d, body, p_local),
            frame_acc=dyn.frame_bias_acc(mx, d, body, p_local), site_acc=dyn.site_bias_acc(mx, d, site),
            com=dyn.com_position(mx, d), com_vel=dyn.com_velocity(mx, d), com_jac=dyn.com_jacobian(mx, d),
            com_acc=dyn.com_bias_acc(mx, d), cmm=dyn.centroidal_momentum_matrix(mx, d),
            momentum=dyn.centroidal_momentum(mx, d), cmm_bias=dyn.centroidal_bias(mx, d),
            p_world=p_world)

    batch = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *[prep(mx, d0, q, v) for q, v in zip(qs, vs)])
    out = jax.jit(jax.vmap(public, in_axes=(None, 0, 0, 0, 0)))(mx, batch, bodies, sites, local)
    out = jax.tree_util.tree_map(np.asarray, out)
    mass = m.body_subtreemass[1]
    for i in range(2):
        d, b, s = _c_data(m, qs[i], vs[i]), bodies[i], sites[i]
        o = {k: x[i] for k, x in out.items()}
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, full)
        _close(o["mass"], full, C_RTOL, "mass_matrix")
        _close(o["bias"], d.qfrc_bias, C_RTOL, "bias_forces")
        assert np.max(np.abs(d.qfrc_passive)) > 1.0
        _close(o["passive"], d.qfrc_passive, C_RTOL, "passive_forces")
        jac = _c_jac(m, d, b, o["p_world"])
        _close(o["point_jac"], jac[:3], C_RTOL, "point_jacobian")
        _close(o["frame_jac"], jac, C_RTOL, "frame_jacobian")
        jp, jr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        mujoco.mj_jacSite(m, d, jp, jr, s)
        _close(o["site_jac"], np.r_[jp, jr], C_RTOL, "site_jacobian")
        acc = _c_jac_dot_qvel(m, d, b, o["p_world"])
        _close(o["point_acc"], acc[:3], C_RTOL, "point_bias_acc")
        _close(o["frame_acc"], acc, C_RTOL, "frame_bias_acc")
        _close(o["site_acc"], _c_jac_dot_qvel(m, d, m.site_bodyid[s], d.site_xpos[s]), C_RTOL, "site_bias_acc")
        _close(o["com"], d.subtree_com[1], C_RTOL, "com_position")
        _close(o["com_vel"], d.subtree_linvel[1], C_RTOL, "com_velocity")
        jc = np.zeros((3, m.nv))
        mujoco.mj_jacSubtreeCom(m, d, jc, 1)
        _close(o["com_jac"], jc, C_RTOL, "com_jacobian")
        _close(o["cmm"][:3], mass * jc, C_RTOL, "centroidal_momentum_matrix, linear rows")
        _close(o["momentum"], np.r_[mass * d.subtree_linvel[1], d.subtree_angmom[1]], C_RTOL, "centroidal_momentum")
        _close(o["com_acc"], o["cmm_bias"][:3] / mass, 1e-12, "com_bias_acc")
        # The CoM acceleration at qacc = 0 is the mass-weighted mean of the body CoMs' bias accelerations.
        body_acc = sum(m.body_mass[k] * _c_jac_dot_qvel(m, d, k, d.xipos[k])[:3] for k in range(1, m.nbody))
        _close(o["com_acc"], body_acc / mass, C_RTOL, "com_bias_acc vs mj_jacDot of the body CoMs")


def test_bad_input_raises(model):
    m, mx, d0 = model
    with pytest.raises(ValueError, match="body_id.*99"):
        dyn.point_jacobian(mx, d0, 99, jnp.zeros(3))
    with pytest.raises(ValueError, match="body_id.*-1"):
        dyn.frame_bias_acc(mx, d0, -1, jnp.zeros(3))
    with pytest.raises(ValueError, match="body_id.*1.5"):
        dyn.point_bias_acc(mx, d0, 1.5, jnp.zeros(3))
    with pytest.raises(ValueError, match=f"site_id.*{m.nsite}"):
        dyn.site_jacobian(mx, d0, m.nsite)
    with pytest.raises(ValueError, match="site_id.*-3"):
        dyn.site_bias_acc(mx, d0, -3)
    with pytest.raises(ValueError, match=r"point_world.*\(2,\)"):
        dyn.frame_jacobian(mx, d0, 3, jnp.zeros(2))
    with pytest.raises(ValueError, match=r"point_local.*\(3, 1\)"):
        dyn.point_bias_acc(mx, d0, 3, jnp.zeros((3, 1)))
    spec = mujoco.MjSpec.from_file(str(__import__("mjx_coman").model_path()))
    spec.geom("l_foot_lower_right_contact").name = "renamed"
    with pytest.raises(ValueError, match="l_foot_lower_right_contact"):
        dyn.foot_contact_points_local(spec.compile())
