"""Region boundaries: safeguarded Newton on the margin vs plain bisection on the grid; the region command."""

import argparse
import json
import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import pytest

from sweeps import region as R

PHASES = np.arange(64) / 64
IMPULSES = np.linspace(0.0, 20.0, 81)  # 0.25 N s apart


@pytest.fixture(scope="module")
def tp():
    ev = R.preset_evaluators("coman", R.RegionSpec(controller="time-projection"))  # shared with the command
    lanes = R.make_lanes([0.0])
    bisection = R.bisection_boundary(ev, lanes, PHASES, IMPULSES)
    newton = R.newton_boundary(ev, lanes, PHASES, (IMPULSES[0], IMPULSES[-1]), tol_ns=0.125)
    return ev, lanes, bisection, newton


def test_newton_finds_the_bisection_boundary_with_5x_fewer_rollouts(tp):
    _, _, bisection, newton = tp
    # Newton stops within its tolerance (0.125 N s) of the soft margin's root: allow that much outside the cell
    same = R.same_within_grid(newton, bisection, slack_ns=0.125)
    assert same.all(), f"differ at phases {PHASES[~same[0]]}"
    assert bisection.rollouts == pytest.approx(64 * 6.3, abs=64)  # about log2(80) per timing
    assert 5 * newton.rollouts <= bisection.rollouts
    assert newton.rollouts * 50 < R.grid_rollouts(1, PHASES, IMPULSES)  # and far fewer than the basin map


def test_the_boundary_separates_recovered_from_fell(tp):
    """One grid step (0.25 N s) under Newton's impulse the walk recovers, one over it falls (plain rollouts).

    The soft margin's root can sit below the hard boundary by more than 0.1 N s (at one timing of 64 with the
    authors' DLQR cost: 17.42 N s against a boundary in [17.5, 17.75]).
    """
    ev, lanes, _, newton = tp
    rows = R._lane_rows(lanes, np.zeros(64, int))
    j = newton.impulse_ns[0]
    below = np.asarray(ev.fell(rows, jnp.asarray(PHASES, jnp.float32), jnp.asarray(j - 0.25, jnp.float32)))
    above = np.asarray(ev.fell(rows, jnp.asarray(PHASES, jnp.float32), jnp.asarray(j + 0.25, jnp.float32)))
    assert not below.any() and above.all()


def test_time_projection_region_is_largest_mid_step(tp):
    """Seed 000: late pushes leave less time to step; the TP boundary peaks past mid-step, lowest at the ends."""
    j = tp[3].impulse_ns[0]
    assert j.min() > 5.0 and j.max() < 20.0
    assert np.argmax(j) > 32 and j[0] < j[40] and j[-1] < j[40]


class _Fake:
    """A margin with a cliff: m = a(phase) - J until J = 2 a, then -50 (J - a); counts its calls."""

    def __init__(self):
        self.calls = 0

    def margin_grad(self, lanes, phase, j):
        self.calls += 1
        phase, j = np.asarray(phase, float), np.asarray(j, float)
        a = 4.0 + 2.0 * phase
        cliff = j > 1.5 * a
        m = np.where(cliff, -50.0 * (j - a), a - j)
        return m, np.where(cliff, -50.0, -1.0), np.full_like(j, 2.0)


def test_safeguard_bisects_where_newton_steps_leave_the_bracket():
    fake = _Fake()
    lanes = R.make_lanes([0.0, 1.0])
    ev = R.Evaluators(fake.margin_grad, None)
    b = R.newton_boundary(ev, lanes, [0.0, 0.5], (0.0, 40.0), tol_ns=1e-3)
    np.testing.assert_allclose(b.impulse_ns, [[4.0, 5.0], [4.0, 5.0]], atol=1e-3)
    assert b.evaluations[0, 1] <= 2  # the tangent along the phase predicts the second root


def _registered() -> bool:
    from sweeps import cli

    return "region" in getattr(cli, "COMMANDS", {})


def test_region_command_draws_the_boundary_over_the_map(tmp_path):
    from sweeps import region_cli

    p = argparse.ArgumentParser()
    region_cli.add_arguments(p)
    args = p.parse_args(["--phases", "4", "--impulses", "0:16:9", "--controllers", "time-projection",
                         "--directions", "forward", "--out", str(tmp_path), "--no-progress"])
    assert region_cli.run(args, p) == 0
    summary = json.loads((tmp_path / "region.json").read_text())
    assert summary["same_within_grid"] and summary["newton_rollouts"] < summary["bisection_rollouts"]
    assert (tmp_path / "map-forward" / "results.npz").exists() or (tmp_path / "map-forward" / "chunks").exists()
    for name in ("boundary.png", "regions.png"):
        assert (tmp_path / name).read_bytes()[:4] == b"\x89PNG"
    before = (tmp_path / "region.json").read_bytes()
    again = p.parse_args(["--phases", "2", "--impulses", "0:16:5", "--controllers", "time-projection",
                          "--directions", "forward", "--out", str(tmp_path), "--no-progress"])
    with pytest.raises(SystemExit) as exc:  # another grid into a finished run: refused before any work
        region_cli.run(again, p)
    assert exc.value.code == 2 and (tmp_path / "region.json").read_bytes() == before


@pytest.mark.skipif(not _registered(), reason="coman-sweep region is not registered in sweeps.cli yet")
@pytest.mark.parametrize("args,word", [(["--impulses", "5,1,3"], "impulses"), (["--phases", "0"], "phases"),
                                       (["--controllers", "pid"], "controller"), (["--draws", "0"], "draws"),
                                       (["--constants", "/nonexistent/tuned.json"], "constants"),
                                       (["--controller", "footstep-mpc"], "'footstep-mpc' for --model 3lp"),
                                       (["--model", "mjx", "--controller", "pid"], "'pid' for --model mjx"),
                                       (["--model", "mjx", "--set", "lqr_weight_scale=1,1,1"], "--model 3lp"),
                                       (["--model", "bullet"], "bullet")])
def test_bad_arguments_exit_2_with_one_line(args, word):
    p = subprocess.run([sys.executable, "-m", "sweeps", "region", *args], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and word in lines[0]
