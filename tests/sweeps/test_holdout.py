"""sweeps.holdout: tuned overrides into held-out sweeps of either model (files, transfer, the controller they reach)."""

import json

import numpy as np
import pytest

from sweeps import holdout
from sweeps.grid import SweepConfig

RECORD = dict(plant="3lp", controller="time-projection", config=dict(seed=0, robot="coman", noise_min_m=5e-4,
                                                                      noise_max_m=1.5e-3, bias_std_m=2e-3),
              overrides_before=dict(deadzone=[0.004, 0.004, 0.04, 0.04], zeta=0.1, window_samples=30.0),
              overrides_after=dict(deadzone=[0.001, 0.002, 0.03, 0.05], zeta=0.25, window_samples=11.6))


def test_held_out_configs_of_each_model_carry_the_overrides():
    for model, window in (("3lp", ("window_samples", 11.6)), ("mjx", ("window", 12))):
        cfgs = holdout.holdout_configs(RECORD, model, RECORD["overrides_after"], phases=(0.5,), impulses_ns=(0.0, 3.0))
        dirs = ["forward", "backward"] + (["left", "right"] if model == "mjx" else [])
        assert [c.direction for c in cfgs] == dirs and all(c.model == model for c in cfgs)
        ov = cfgs[0].overrides()
        assert ov["zeta"] == 0.25 and ov[window[0]] == window[1] and ov["deadzone"] == (0.001, 0.002, 0.03, 0.05)
        assert cfgs[0].seed == 1  # the tuning seed + 1: other noise than training's


def test_the_default_held_out_grids_hold_at_least_200_walks_per_set():
    for model in ("3lp", "mjx"):
        assert sum(c.n_rollouts for c in holdout.holdout_configs(RECORD, model, {})) >= 200


def test_the_sets_are_compared_pair_by_pair(fake_run):
    cfg = SweepConfig(model="mjx", phases=(0.0, 0.5), impulses_ns=(1.0, 2.0, 3.0, 4.0)).validate()
    seed, tuned = fake_run(cfg, lambda g, i: 2.0), fake_run(cfg, lambda g, i: 4.0 if g.phase[i] else 1.0)
    t = holdout.compare({"seed": [seed], "tuned": [tuned]})
    p = t["paired"]
    assert (p["pairs"], p["both"], p["seed_only"], p["tuned_only"], p["neither"]) == (8, 3, 1, 2, 2)
    assert p["seed_rate"] == t["seed"]["recovery_rate"] == 0.5 and p["mcnemar_p"] == 1.0
    assert "paired over 8 walks" in holdout.format_table(dict(t, seed=dict(t["seed"], wall_s=1.0)))


def test_non_finite_walks_are_named_in_the_table(fake_run):
    cfg = SweepConfig(model="mjx", phases=(0.0, 0.5), impulses_ns=(1.0, 2.0)).validate()
    seed, tuned = fake_run(cfg, lambda g, i: 2.0), fake_run(cfg, lambda g, i: 2.0)
    tuned.results["nan"] = np.arange(4) < 3  # three of the four walks blew up
    t = holdout.compare({"seed": [seed], "tuned": [tuned]})
    text = holdout.format_table(t)
    assert "of 1 finite (3 of 4 non-finite)" in text and "non-finite walk counts as not recovered" in text
    assert t["paired"]["tuned_rate"] == 0.25 and t["tuned"]["recovery_rate"] == 1.0


def test_failed_solves_are_counted_in_the_table(fake_run):
    from sweeps.runner import failure_reason

    cfg = SweepConfig(model="mjx", phases=(0.0, 0.5), impulses_ns=(1.0, 2.0, 3.0)).validate()
    seed, tuned = fake_run(cfg, lambda g, i: 2.0), fake_run(cfg, lambda g, i: 2.0)
    r = tuned.results
    r["reason"] = failure_reason(r["fell"], r["nan"], r["fell"] & (r["phase"] > 0))  # one of the two falls
    t = holdout.compare({"seed": [seed], "tuned": [tuned]})
    assert (t["seed"]["solve_failed"], t["tuned"]["solve_failed"]) == (0, 1)
    assert [d["solve_failed"] for d in t["tuned"]["per_direction"]] == [1]
    text = holdout.format_table(t)
    assert "tuned constants: 66.7% of 6 recovered, 1 ended by a failed solve;" in text, text
    assert "seed constants: 66.7% of 6 recovered;" in text, text


def test_flat_and_record_files_give_the_overrides(tmp_path):
    (tmp_path / "t.json").write_text(json.dumps(RECORD))
    assert holdout.load_overrides(tmp_path / "t.json") == RECORD["overrides_after"]
    assert holdout.load_overrides(tmp_path / "t.json", "before")["zeta"] == 0.1
    (tmp_path / "f.json").write_text('{"zeta": 0.3}')
    assert holdout.load_overrides(tmp_path / "f.json") == {"zeta": 0.3}


@pytest.mark.parametrize("text, match", [("{not json", "cannot read"), ("[1, 2]", "no settings"),
                                         ('{"config": {}, "plant": "3lp"}', "no controller overrides")])
def test_bad_constants_files_name_the_problem(tmp_path, text, match):
    path = tmp_path / "c.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        holdout.load_overrides(path)


def test_overrides_reach_the_walking_controller():
    from sweeps.models import mjx

    cfg = SweepConfig(model="mjx").with_overrides(dict(deadzone=(0.001, 0.002, 0.03, 0.05), zeta=0.25,
                                                       window=12)).validate()
    _, ctrl = mjx.controller(cfg)
    np.testing.assert_allclose(np.asarray(ctrl.deadzone), (0.001, 0.002, 0.03, 0.05), rtol=1e-6)
    assert float(ctrl.zeta) == pytest.approx(0.25) and ctrl.window == 12


@pytest.mark.parametrize("args, word", [
    (["map", "--constants", "MISSING"], "cannot read constants"),
    (["map", "--model", "mjx", "--constants", "MISSING"], "cannot read constants"),
    (["map", "--model", "mjx", "--set", "zeta=2"], "zeta"),
    (["map", "--model", "mjx", "--set", "window_samples=3"], "unknown setting 'window_samples'"),
    (["map", "--model", "3lp", "--set", "window=3"], "unknown setting 'window'"),
    (["map", "--model", "mjx", "--controller", "nope"], "unknown controller 'nope'"),
    (["compare", "--model", "3lp", "--controllers", "no-deadzone"], "no-deadzone"),
])
def test_controller_option_errors_exit_2(args, word, tmp_path, capsys):
    from sweeps.cli import main

    with pytest.raises(SystemExit) as exc:
        main([a.replace("MISSING", str(tmp_path / "none.json")) for a in args] + ["--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and len(err.strip().splitlines()) == 1 and word in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_held_out_mjx_sweeps_of_a_record_and_their_resume(tmp_path):
    """1 m / 10 m/s dead-zones (no footstep adjustment) topple a push that the seed's constants recover."""
    record = dict(RECORD, overrides_before=dict(deadzone=[0.004, 0.004, 0.04, 0.04], zeta=0.1, window=30),
                  overrides_after=dict(deadzone=[1.0, 1.0, 10.0, 10.0], zeta=0.1, window=30))
    grid = dict(directions=("backward",), phases=(0.375,), impulses_ns=(0.0, 6.0), chunk=2)
    out = holdout.run_holdout(record, tmp_path, model="mjx", progress=False, workers=1, **grid)
    seed, tuned = (out["runs"][n][0].results for n in holdout.SETS)
    assert not seed["fell"].any() and tuned["fell"][1] and not tuned["fell"][0]
    table = json.loads((tmp_path / "holdout.json").read_text())
    assert table["model"] == "mjx" and table["seed"]["recovery_rate"] == 1.0
    assert (tmp_path / "holdout.png").stat().st_size > 1000
    again = holdout.run_holdout(record, tmp_path, model="mjx", progress=False, workers=1, **grid)
    assert all(r.timing["chunks_run"] == 0 for lst in again["runs"].values() for r in lst)
