"""The tuning objective: exact gradients, valid parametrisation, a margin that tells falls, Figure 9 thresholds."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from sweeps import objective as O

SPEC = O.ObjectiveSpec(n_steps=5, push_step=1, tune_weights=True)


@pytest.fixture(scope="module")
def x64():
    with jax.enable_x64(True):
        yield


@pytest.fixture(scope="module")
def coman(x64):
    from jaxlp.presets import get_params

    return get_params("coman")


IMPULSES = jnp.linspace(0.0, 14.0, 8)


@pytest.fixture(scope="module")
def problem(coman):
    """Eight forward pushes at phase 0.4 from 0 to 14 N s, so both terms of the loss are active.

    Returns ``value_and_grad`` of the loss (one compilation serves every test),
    the point, and its loss, per-rollout costs and gradient.
    """
    sc = O.sample_scenarios(jax.random.PRNGKey(3), 8)
    one_draw = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x[0], x.shape), sc)  # the same sensors for all
    sc = one_draw._replace(impulse_ns=IMPULSES, phase=jnp.full(8, 0.4), direction_rad=jnp.zeros(8))
    c = O.make_constants([2e-3, 2e-3, 2e-2, 1.5e-2], zeta=0.12, window_samples=27.4, weight_scale=(1.0, 1.3, 0.8))
    lateral = jnp.array([3e-4, 1.5e-3, 7e-3, 3e-2])
    value_grad = jax.jit(jax.value_and_grad(lambda r: O.objective(r, coman, lateral, sc, SPEC), has_aux=True))
    raw = O.to_raw(c, SPEC.window_max)
    (loss, costs), grad = value_grad(raw)
    return value_grad, raw, loss, costs, grad


def _perturb(raw, field, index, eps):
    val = getattr(raw, field)
    new = val + eps if val.ndim == 0 else val.at[index].add(eps)
    return dataclasses.replace(raw, **{field: new})


@pytest.mark.parametrize("field,index", [("log_deadzone", 0), ("log_deadzone", 1), ("log_deadzone", 2),
                                         ("log_deadzone", 3), ("logit_zeta", None), ("logit_window", None),
                                         ("log_weight_scale", 1)])
def test_gradient_matches_central_differences(problem, field, index):
    value_grad, raw, _, _, grad = problem
    loss = lambda r: float(value_grad(r)[0][0])  # noqa: E731
    g = getattr(grad, field)
    g = float(g if index is None else g[index])
    eps = 1e-5
    fd = (loss(_perturb(raw, field, index, eps)) - loss(_perturb(raw, field, index, -eps))) / (2 * eps)
    assert np.isfinite(g)
    assert g == pytest.approx(fd, rel=2e-4, abs=1e-7)


def test_gradient_reaches_every_tuned_constant(problem):
    grad = problem[-1]
    leaves = jnp.concatenate([jnp.ravel(x) for x in jax.tree_util.tree_leaves(grad)])
    assert bool(jnp.all(jnp.isfinite(leaves)))
    assert int(jnp.sum(jnp.abs(leaves) > 1e-9)) == leaves.size


@pytest.mark.parametrize("scale", [-50.0, -3.0, 0.0, 3.0, 50.0])
def test_any_raw_point_gives_valid_constants(scale, x64):
    raw = O.RawConstants(jnp.full(4, scale), jnp.asarray(scale), jnp.asarray(scale), jnp.full(3, scale / 10))
    c = O.from_raw(raw, 60)
    assert bool(jnp.all(c.deadzone > 0)) and 0.0 <= float(c.zeta) <= 1.0
    assert 1.0 <= float(c.window_samples) <= 60.0 and bool(jnp.all(c.weight_scale > 0))


def test_raw_round_trip(x64):
    c = O.make_constants([1e-3, 2e-3, 3e-2, 4e-2], zeta=0.1, window_samples=30.0, weight_scale=(2.0, 0.5, 1.0))
    back = O.from_raw(O.to_raw(c, 60), 60)
    for a, b in zip(jax.tree_util.tree_leaves(c), jax.tree_util.tree_leaves(back)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12)
    assert O.constants_from_dict(c.as_dict()).as_dict() == pytest.approx(c.as_dict(), rel=1e-12)


def test_margin_sign_is_the_fall_and_continuous_in_the_push(problem):
    """Hard margin < 0 exactly when the rollout fell; the soft one sits just below; no jump at the boundary."""
    costs = problem[3]
    hard, soft, fell = (np.asarray(x) for x in (costs.hard_margin, costs.margin, costs.fell))
    np.testing.assert_array_equal(hard < 0, fell)
    assert not fell[0] and fell[-1]  # no push recovers, 14 N s does not
    assert np.all(soft <= hard + 1e-12) and np.all(hard - soft <= SPEC.margin_temperature * np.log(5 * 200 * 2 + 5))
    assert np.max(np.abs(np.diff(hard))) < 0.15  # 2 N s apart: a continuous function of the push


def test_both_terms_of_the_loss_respond_to_the_push(problem):
    costs = problem[3]
    fall = np.asarray(costs.fall)
    assert fall[0] < 0.05 and fall[-1] > 0.95  # the smooth fall indicator agrees with the outcome far from it
    assert np.asarray(costs.error)[-1] > np.asarray(costs.error)[0]  # a hard push leaves larger landing errors


@pytest.fixture(scope="module")
def figure9(coman):
    return jax.jit(lambda s, zeta: O.figure9_thresholds(coman, SPEC, s, zeta=zeta))


@pytest.mark.parametrize("zeta", [0.1, 0.3])
def test_figure9_thresholds_of_white_noise_follow_the_iir_variance(figure9, zeta):
    """Without bias, the sagittal position thresholds are the IIR's output std: sigma sqrt(zeta / (2 - zeta))."""
    sigma = 1e-3
    dist = O.ScenarioDistribution(noise_std_m=(sigma, sigma), quantisation_m=0.0, bias_std_m=0.0)
    sc = O.sample_scenarios(jax.random.PRNGKey(2), 4, dist)
    th = figure9(sc, zeta)
    expected = sigma * np.sqrt(zeta / (2 - zeta))
    np.testing.assert_allclose(np.asarray(th[0, :2]), expected, rtol=0.1)
    assert float(th[1, 1]) > float(th[0, 1])  # the lateral pelvis error also holds the filter's lag on the sway


def test_figure9_thresholds_grow_with_the_bias(figure9):
    sc = O.sample_scenarios(jax.random.PRNGKey(2), 4, O.ScenarioDistribution(bias_std_m=0.0))
    biased = sc._replace(bias_m=sc.bias_m.at[:, 0, 1].set(3e-3))
    clean, bias = np.asarray(figure9(sc, 0.1)), np.asarray(figure9(biased, 0.1))
    assert bias[0, 1] == pytest.approx(np.hypot(clean[0, 1], 3e-3), rel=0.02)  # RMS about zero
    np.testing.assert_allclose(bias[0, 3], clean[0, 3], rtol=1e-6)  # a constant bias has no velocity


@pytest.mark.parametrize("kwargs,match", [
    (dict(deadzone=[1e-3, 0.0, 1e-2, 1e-2]), "deadzone"),
    (dict(deadzone=[1e-3, 1e-3]), "deadzone"),
    (dict(deadzone=[1e-3] * 4, zeta=1.0), "zeta"),
    (dict(deadzone=[1e-3] * 4, window_samples=0.5), "window_samples"),
    (dict(deadzone=[1e-3] * 4, weight_scale=(1.0, -1.0, 1.0)), "weight_scale"),
])
def test_bad_constants_raise(kwargs, match):
    with pytest.raises(ValueError, match=match):
        O.make_constants(**kwargs)


@pytest.mark.parametrize("kwargs,match", [(dict(impulse_max_ns=-1.0), "impulse_max_ns"),
                                           (dict(zero_push_fraction=1.5), "zero_push_fraction"),
                                           (dict(noise_std_m=(2e-3, 1e-3)), "noise_std_m"),
                                           (dict(bias_std_m=-1.0), "bias_std_m")])
def test_bad_distribution_raises(kwargs, match):
    with pytest.raises(ValueError, match=match):
        O.sample_scenarios(jax.random.PRNGKey(0), 4, O.ScenarioDistribution(**kwargs))
