"""``python -m mjx_coman.studies``: bad input exits 2 with one line before anything is built (the run itself:
tests/mjx_coman/test_notebook_06.py)."""

import pytest

from mjx_coman.studies import cli


@pytest.fixture
def no_build(monkeypatch):
    from mjx_coman.studies import batch

    def boom(*a, **k):
        raise AssertionError("ran a walk before validating the arguments")

    monkeypatch.setattr(batch, "run_rows", boom)


@pytest.mark.parametrize("args,word", [
    (["walkies"], "walkies"),
    (["steer", "--controller", "time-projection"], "does not steer"),
    (["speeds", "--controller", "robocop"], "robocop"),
    (["speeds", "--plot", "x.gif"], "--plot"),
    (["speeds", "--plot", "/no/such/dir/x.png"], "--plot"),
    (["speeds", "--out", "/no/such/dir/x.json"], "--out"),
    (["speeds", "--batch", "0"], "--batch"),
    (["speeds", "--seed", "-3"], "seed=-3"),
    (["speeds", "--set", "bogus=1"], "bogus"),
    (["speeds", "--set", "encoder_filter_s=-1"], "encoder_filter_s"),
])
def test_bad_arguments_exit_2_with_one_line(args, word, capsys, no_build):
    assert cli.main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and word in err and err.startswith(cli.PROG)


def test_an_existing_out_file_is_not_replaced_without_force(tmp_path, capsys, no_build):
    out = tmp_path / "speeds.json"
    out.write_text("{}")
    assert cli.main(["speeds", "--out", str(out)]) == 2
    assert "--force" in capsys.readouterr().err and out.read_text() == "{}"


def test_unknown_size_is_an_argparse_error(capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["speeds", "--size", "huge"])
    assert e.value.code == 2 and capsys.readouterr().err.count("\n") == 1


@pytest.mark.slow
def test_a_small_experiment_prints_strict_json_and_draws_its_figure(tmp_path, tmp_path_factory):
    """The same compiled walk as notebook 06's small experiments (JAX's persistent cache, shared). Slow (about
    100 s with the compilation): the default suite runs the studies through notebook 06."""
    import json
    import os
    import subprocess
    import sys

    env = dict(os.environ, JAX_COMPILATION_CACHE_DIR=str(tmp_path_factory.getbasetemp() / "jax_compile_cache"))
    plot, out = tmp_path / "delay.png", tmp_path / "delay.json"
    p = subprocess.run([sys.executable, "-m", "mjx_coman.studies", "delay", "--size", "small", "--json", "--quiet",
                        "--plot", str(plot), "--out", str(out)], capture_output=True, text=True, timeout=600, env=env)
    assert p.returncode == 0, p.stderr[-2000:]
    result = json.loads(p.stdout, parse_constant=lambda c: pytest.fail(f"non-strict JSON constant {c}"))
    assert json.loads(out.read_text()) == result and plot.stat().st_size > 10_000
    assert result["experiment"] == "delay" and len(result["rows"]) == 2
    for row in result["rows"]:  # ground truth of a 1.2 s walk with 10 ms and 2 ms of delay
        assert row["delay_ms"] in (10.0, 2.0) and isinstance(row["fell"], bool) and row["touchdowns"] >= 0
        assert (row["fall_time_s"] is None) == (not row["fell"])
