"""coman-sweep tune: a tiny optax run lowers the loss and writes valid outputs; held-out sweeps; bad arguments."""

import json
import subprocess
import sys

import numpy as np
import pytest

from sweeps import holdout, objective as O, tune


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("tune")
    cfg = tune.TuneConfig(steps=3, batch=4, n_steps=4, learning_rate=0.1)
    record = tune.tune(cfg, progress=False)
    record["command"] = "test"
    tune.write_outputs(out, record)
    return out, record


def test_a_finished_run_is_not_replaced_without_force(tiny_run, capsys):
    from sweeps import cli

    out, _ = tiny_run
    before = (out / "tuned.json").read_bytes()
    with pytest.raises(SystemExit) as exc:
        cli.main(["tune", "--out", str(out), "--no-progress"])
    assert exc.value.code == 2 and "already holds tuned.json: use --force" in capsys.readouterr().err
    assert (out / "tuned.json").read_bytes() == before


def test_tiny_budget_lowers_the_training_loss(tiny_run):
    _, record = tiny_run
    loss = record["history"]["loss"]
    assert len(loss) == 4 and all(np.isfinite(loss))
    assert loss[-1] < loss[0]  # the last iterate, not just the best one
    assert record["loss_after"] == pytest.approx(min(loss)) and record["loss_after"] < record["loss_before"]


def test_outputs_are_valid_json_and_png(tiny_run):
    out, record = tiny_run
    saved = json.loads((out / "tuned.json").read_text())
    assert saved["command"] == "test" and saved["plant"] == "3lp"
    before = O.constants_from_dict(saved["constants_before"])
    after = O.constants_from_dict(saved["constants_after"])  # valid constants (raises otherwise)
    assert float(before.zeta) == pytest.approx(0.1) and float(before.window_samples) == pytest.approx(30.0)
    assert saved["constants_after"] != saved["constants_before"]
    np.testing.assert_allclose(np.asarray(after.weight_scale), 1.0)  # weights not tuned unless asked
    # the overrides stand for the constants: the 3lp controller's settings
    ov = saved["overrides_after"]
    assert ov["zeta"] == pytest.approx(saved["constants_after"]["zeta"])
    assert ov["deadzone"][1] == pytest.approx(saved["constants_after"]["deadzone_pelvis_position_m"])
    assert len(ov["lateral_deadzone"]) == 4 and ov["lateral_deadzone"] == saved["lateral_deadzone"]
    assert np.isfinite(saved["heldout_loss_before"]) and np.isfinite(saved["heldout_loss_after"])
    assert (out / "loss.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(out.glob(".*.tmp"))  # atomic writes leave no temporary files


def test_seed_thresholds_come_from_figure9_of_the_training_sensors(tiny_run):
    _, record = tiny_run
    c = record["constants_before"]
    # 1 mm noise and 2 mm bias: position thresholds of a few mm, velocity thresholds of a few cm/s
    assert 5e-4 < c["deadzone_swing_position_m"] < 5e-3 and 5e-4 < c["deadzone_pelvis_position_m"] < 5e-3
    assert 2e-3 < c["deadzone_swing_velocity_mps"] < 0.1 and 2e-3 < c["deadzone_pelvis_velocity_mps"] < 0.1


def test_holdout_sweeps_recover_small_pushes_and_not_huge_ones(tiny_run, tmp_path):
    """The held-out 3LP sweeps of the record run through the sweep runner: outputs, resume, the load round trip."""
    _, record = tiny_run
    grid = dict(directions=("forward",), phases=(0.25, 0.75), impulses_ns=(0.0, 2.0, 40.0), n_steps=6, chunk=4)
    out = holdout.run_holdout(record, tmp_path, progress=False, workers=1, **grid)
    runs, table = out["runs"], out["table"]
    for name in holdout.SETS:
        res = runs[name][0].results
        assert runs[name][0].config.overrides()["zeta"] == pytest.approx(record[f"overrides_{'before' if name == 'seed' else 'after'}"]["zeta"])
        assert res["fell"].shape == (6,) and set(res["reason"]) <= {"", "fell", "nan"}
        np.testing.assert_array_equal(res["fell"].reshape(2, 3), [[False, False, True], [False, False, True]])
        s = table[name]["per_direction"][0]
        assert s["recovery_rate"] == pytest.approx(4 / 6) and s["undisturbed_fell"] == 0
        assert [r["max_recovered_impulse_ns"] for r in s["per_phase"]] == [2.0, 2.0]
        assert np.all(np.isfinite(res["late_error"]))
    saved = json.loads((tmp_path / "holdout.json").read_text())
    assert saved["model"] == "3lp" and saved["seed"]["rollouts"] == 6
    back = holdout.load_runs(tmp_path / "holdout.npz")["tuned"][0]
    assert back.config == runs["tuned"][0].config
    np.testing.assert_array_equal(back.results["fell"], runs["tuned"][0].results["fell"])
    again = holdout.run_holdout(record, tmp_path, progress=False, workers=1, **grid)  # resumes every chunk
    assert all(r.timing["chunks_run"] == 0 for lst in again["runs"].values() for r in lst)


def test_overrides_transfer_between_models():
    from mjx_coman import controllers

    ov = {"deadzone": [0.001, 0.002, 0.03, 0.04], "zeta": 0.12, "window_samples": 27.6, "lateral_deadzone": [1, 1, 1, 1]}
    out = holdout.transfer_overrides(ov, controllers.get("time-projection").settings)
    assert out == {"deadzone": (0.001, 0.002, 0.03, 0.04), "zeta": 0.12, "window": 28}  # whole samples on MJX


@pytest.mark.parametrize("field,value", [("steps", 0), ("batch", 0), ("learning_rate", -1.0), ("n_steps", 3),
                                         ("optimizer", "lbfgs"), ("plant", "mujoco"), ("noise_max_m", 1e-4),
                                         ("bias_std_m", -1e-3), ("controller", "open-loop"),
                                         ("learning_rate", float("inf"))])
def test_bad_config_raises(field, value):
    with pytest.raises(ValueError, match=field.split("_")[0]):
        tune.TuneConfig(**{field: value}).validate()


@pytest.mark.parametrize("args,word", [(["--steps", "0"], "steps"), (["--optimizer", "newton"], "optimizer"),
                                       (["--plant", "mujoco"], "plant"), (["--noise-max", "1e-5"], "noise_max"),
                                       (["--lr", "0"], "learning_rate"), (["--lr", "inf"], "learning_rate"),
                                       (["--plant", "mjx", "--controller", "nope"], "time-projection"),
                                       (["--plant", "mjx", "--set", "bogus=1"], "bogus"),
                                       (["--plant", "3lp", "--set", "zeta=0.2"], "--set"),
                                       (["--plant", "mjx", "--tune", "step_time_s"], "step_time_s"),
                                       (["--out", "/proc/x"], "/proc")])
def test_bad_arguments_exit_2_with_one_line(args, word):
    p = subprocess.run([sys.executable, "-m", "sweeps", "tune", *args], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and word in lines[0]


def test_the_kept_iterate_falls_least_before_it_sways_least(monkeypatch):
    """A problem whose loss keeps falling while the iterates past 0.5 fall on both training pushes (as a walk
    frozen by a fall sways less): the tuner keeps the last iterate that did not fall, not the lowest loss."""
    import jax.numpy as jnp

    from sweeps import models
    from sweeps.models import Model, TuneProblem

    def value_and_grad(raw, split):
        x = raw["x"]
        fell = jnp.full(2, x > 0.5)
        return ((1.0 - x) ** 2, dict(fell=fell)), dict(x=-2.0 * (1.0 - x))

    problem = TuneProblem(raw0=dict(x=jnp.asarray(0.0)), value=lambda raw, split: value_and_grad(raw, split)[0],
                          value_and_grad=value_and_grad, constants=lambda raw: dict(x=float(raw["x"])),
                          overrides=lambda raw: dict(x=float(raw["x"])), info={})
    fake = Model(None, lambda config: 1, tune_problem=lambda tc: problem)
    monkeypatch.setattr(models, "get_model", lambda name: fake)
    rec = tune.tune(tune.TuneConfig(steps=12, learning_rate=0.1, optimizer="sgd"), progress=False)
    assert min(rec["history"]["loss"]) < rec["loss_after"]  # a lower loss was seen, on an iterate that fell
    assert rec["fell_rate_after"] == 0.0 and rec["constants_after"]["x"] <= 0.5


def test_each_walking_controller_has_settings_to_tune_and_a_default_plant():
    from mjx_coman import controllers

    for name in controllers.names(walking=True):
        ctrl = controllers.get(name)
        chosen = ctrl.tune_default or ctrl.tunables()
        assert chosen and set(chosen) <= set(ctrl.tunables()), name
    assert controllers.get("footstep-mpc").tune_default[0].startswith("mpc_")  # seed 001's MPC weights, gains
    assert tune.default_plant("time-projection", False) == "3lp" and tune.default_plant("dlqr", False) == "3lp"
    assert tune.default_plant("time-projection", True) == "mjx" and tune.default_plant("footstep-mpc", False) == "mjx"


@pytest.mark.slow
def test_mjx_forward_mode_gradient_agrees_with_central_differences():
    """Through contact (the MJX tuning problem, float64), the forward-mode gradient of the ground-truth sway
    against central differences in the unconstrained coordinates. The loss is piecewise smooth: a contact that
    starts one tick earlier moves it by about 1.6e-3 (measured), so a difference straddling such a jump is off
    by jump / (2 eps); at 1e-4 and 1e-5 some do, at 1e-6 none (measured). Each constant must agree at two of
    three steps 1e-6, 2e-6, 4e-6, so one straddled jump cannot fail it and a wrong derivative cannot pass."""
    import jax
    import jax.numpy as jnp

    from sweeps.models import get_model

    with jax.enable_x64(True):
        p = get_model("mjx").tune_problem(tune.TuneConfig(plant="mjx", batch=1, impulse_max_ns=3.0, x64=True))
        (loss, _), grad = p.value_and_grad(p.raw0, "train")
        assert np.isfinite(float(loss)) and float(loss) > 0
        value = lambda raw: float(p.value(raw, "train")[0])  # noqa: E731
        for name, g in grad.items():
            for i in range(np.size(g)):
                ad, fds = float(np.ravel(g)[i]), []
                for eps in (1e-6, 2e-6, 4e-6):
                    e = jnp.zeros_like(p.raw0[name]).reshape(-1).at[i].set(eps).reshape(np.shape(p.raw0[name]))
                    fds.append((value(dict(p.raw0, **{name: p.raw0[name] + e}))
                                - value(dict(p.raw0, **{name: p.raw0[name] - e}))) / (2 * eps))
                agree = [abs(fd - ad) <= 1e-4 + 1e-2 * abs(fd) for fd in fds]
                assert sum(agree) >= 2, f"{name}[{i}]: forward mode {ad:.6g}, central differences {fds}"
