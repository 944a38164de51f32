"""Every command line refuses bad input the same way: exit status 2, one line on stderr naming the value,
no traceback, and nothing left behind in the output folder (issue 22's table, in process: no compile)."""

import importlib

import pytest

ENTRY_POINTS = {  # name -> module whose main(argv) the console script or ``python -m`` runs
    "jaxlp": "jaxlp.__main__", "walk": "mjx_coman.walk", "seed000": "mjx_coman.seed000.cli",
    "experiments": "mjx_coman.experiments", "studies": "mjx_coman.studies.cli", "coman-sweep": "sweeps.cli",
    "mjcf": "mjx_coman.mjcf",
}
OUT = "OUT"  # replaced by a fresh folder under tmp_path, which must stay absent

CASES = [
    ("jaxlp", ["info", "--step-width", "100"], "step_width_m"),
    ("jaxlp", ["info", "--speed", "5"], "speed_mps"),
    ("jaxlp", ["info", "--step-time", "1000"], "step_time_s"),
    ("jaxlp", ["info", "--robot", "foo"], "foo"),
    ("walk", ["--seconds", "nan"], "--seconds"),
    ("walk", ["--plot", "/proc/x.png"], "/proc/x.png"),
    ("walk", ["--seed", str(2**70)], "--seed"),
    ("walk", ["--push-phase", "1.5"], "--push-phase"),
    ("seed000", ["push-table", "--seed", str(2**70)], "--seed"),
    ("seed000", ["push-table", "--supply-v", "-1"], "supply_v"),
    ("seed000", ["identify", "--seconds", "1", "--settle", "5"], "settle_s"),
    ("experiments", ["stand", "--duration", "0"], "--duration"),
    ("experiments", ["stand", "--duration", "nan"], "--duration"),
    ("experiments", ["knee", "--duration", "3"], "--duration"),
    ("experiments", ["ankle", "--spring", "nan"], "spring_stiffness"),
    ("studies", ["speeds", "--plot", "/proc/x.png"], "/proc/x.png"),
    ("studies", ["speeds", "--seed", "-1"], "seed"),
    ("coman-sweep", ["map", "--push-duration", "inf", "--out", OUT], "push_duration_s"),
    ("coman-sweep", ["map", "--bias", "nan", "--out", OUT], "bias_m"),
    ("coman-sweep", ["map", "--speed", "5", "--out", OUT], "infeasible"),
    ("coman-sweep", ["map", "--step-time", "1000", "--out", OUT], "step_time_s"),
    ("coman-sweep", ["map", "--model", "mjx", "--robot", "foo", "--out", OUT], "robot"),
    ("coman-sweep", ["map", "--n-steps", "1000000000", "--out", OUT], "n_steps"),
    ("coman-sweep", ["map", "--seed", str(2**70), "--out", OUT], "seed"),
    ("coman-sweep", ["map", "--impulses", "0:20:1000000000", "--out", OUT], "--impulses"),
    ("coman-sweep", ["map", "--phases", "10000", "--impulses", "0:20:10000", "--out", OUT], "GB of results"),
    ("coman-sweep", ["compare", "--controllers", "dlqr,pid", "--out", OUT], "'pid'"),
    ("coman-sweep", ["tune", "--lr", "inf", "--out", OUT], "learning_rate"),
    ("coman-sweep", ["tune", "--seed", str(2**70), "--out", OUT], "seed"),
    ("coman-sweep", ["tune", "--batch", "1000000000", "--out", OUT], "batch"),
    ("coman-sweep", ["region", "--draws", "0", "--out", OUT], "draws"),
    ("coman-sweep", ["region", "--out", "/proc/x"], "/proc"),
    ("coman-sweep", ["map", "--model", "3lp", "--engine", "native", "--out", OUT], "--model mjx only"),
    ("coman-sweep", ["engines", "--controllers", "nope", "--out", OUT], "unknown controller 'nope'"),
    ("coman-sweep", ["engines", "--directions", "up", "--out", OUT], "unknown direction 'up'"),
    ("coman-sweep", ["engines", "--seconds", "0", "--out", OUT], "--seconds"),
    ("mjcf", ["--bogus"], "--bogus"),
]


def _runnable_modules():
    """Every module a user can run: ``X/__main__.py`` (resolved to the module it takes ``main`` from) and
    every module with an ``if __name__ == "__main__"`` block, under the three packages."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    found = set()
    for pkg in ("jaxlp", "mjx_coman", "sweeps"):
        for path in (root / pkg).rglob("*.py"):
            mod = ".".join(path.relative_to(root).with_suffix("").parts)
            tree = ast.parse(path.read_text())
            if path.name == "__main__.py":
                src = [n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)
                       and any(a.name == "main" for a in n.names)]
                found.add(src[0] if src else mod)
            elif any(isinstance(n, ast.If) and "__main__" in ast.unparse(n.test) for n in tree.body):
                found.add(mod)
    return found


def test_every_runnable_module_is_in_the_table():
    assert _runnable_modules() <= set(ENTRY_POINTS.values())
    assert {ENTRY_POINTS[c[0]] for c in CASES} == set(ENTRY_POINTS.values())  # each has a bad-input case


@pytest.fixture(autouse=True)
def _jax_float_width_untouched():
    """No command line's ``main`` may change JAX's float width for the rest of the process (``python -m
    jaxlp`` once turned 64-bit floats on for good, and the float32 MJX tests after it in the worker failed)."""
    import jax

    x64 = jax.config.jax_enable_x64
    yield
    assert jax.config.jax_enable_x64 == x64


@pytest.mark.parametrize("name,argv,word", CASES, ids=[f"{c[0]}:{' '.join(c[1][:3])}" for c in CASES])
def test_bad_input_is_one_line_exit_2_and_leaves_nothing(name, argv, word, tmp_path, capsys):
    out = tmp_path / "out"
    argv = [str(out) if a == OUT else a for a in argv]
    main = importlib.import_module(ENTRY_POINTS[name]).main
    try:
        code = main(argv)
    except SystemExit as e:  # argparse's own refusals
        code = e.code
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "Failed to import warp" not in line]
    assert code == 2, err
    assert len(lines) == 1 and word in lines[0] and "Traceback" not in err, err
    assert not out.exists()
