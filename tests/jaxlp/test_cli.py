"""``python -m jaxlp info``: the JSON report and one-line errors with exit status 2."""

import json
import subprocess
import sys

import pytest


def _run(*args):
    return subprocess.run([sys.executable, "-m", "jaxlp", *args], capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def report():
    out = _run("info", "--robot", "coman", "--step-time", "0.4", "--speed", "0.1", "--json")
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def test_report_parameters_and_gait(report):
    assert report["params"]["m1"] == pytest.approx(14.17, rel=1e-6)
    assert report["params"]["I2"] == pytest.approx(0.207492, rel=1e-5)
    g = report["gait"]
    assert g["pelvis_velocity_start_mps"][0] == pytest.approx(0.13353, abs=1e-5)
    assert abs(g["pelvis_velocity_start_mps"][1]) == pytest.approx(0.215035, abs=1e-6)
    assert g["hip_torque_const_nm"] == pytest.approx([-2.12209, 0.868937], abs=1e-5)
    assert g["hip_torque_rate_nms"] == pytest.approx([10.6105, 0.0], abs=1e-4)


def test_report_eigenvalues(report):
    open_mag = max(abs(complex(*z)) for z in report["eigenvalues_open_loop"])
    closed_mag = max(abs(complex(*z)) for z in report["eigenvalues_closed_loop"])
    assert len(report["eigenvalues_open_loop"]) == 4
    assert open_mag > 1.0 > closed_mag
    # the authors' foot exchange: a real unstable eigenvalue above 3 and translation invariance's 1
    assert report["conventions"] == {"exchange": "authors", "cost": "authors", "cost_mass_kg": pytest.approx(28.5)}
    unstable = [z for z in report["eigenvalues_open_loop"] if abs(complex(*z)) > 1.5]
    assert len(unstable) == 1 and unstable[0][0] > 3.0 and unstable[0][1] == pytest.approx(0.0, abs=1e-9)
    assert min(abs(complex(*z) - 1.0) for z in report["eigenvalues_open_loop"]) < 1e-9


def test_report_footstep_gains(report):
    fg = report["footstep_gains"]
    assert fg["phase"] == pytest.approx([0.1 * i for i in range(10)])
    for name in ("swing_position", "pelvis_position", "swing_velocity", "pelvis_velocity"):
        assert len(fg[name]) == 10
    assert fg["pelvis_position"][0] > fg["pelvis_position"][5] > 0  # Figure 13 B


def test_table_output():
    out = _run("info", "--step-width", "0.1", "--phases", "0,0.5")
    assert out.returncode == 0, out.stderr
    assert "footstep gains" in out.stdout and "0.50" in out.stdout


@pytest.mark.parametrize(
    "args,word",
    [(["info", "--robot", "asimo"], "--robot"), (["info", "--speed", "2.0"], "infeasible"),
     (["info", "--step-time", "-0.4"], "step_time_s"), (["info", "--phases", "0,1.5"], "--phases"),
     (["info", "--speed", "fast"], "--speed"), ([], "command")],
)
def test_bad_arguments_exit_2_with_one_line(args, word):
    out = _run(*args)
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and word in lines[0]
