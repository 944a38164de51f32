"""The command lines' shared refusals: one line, exit 2, outputs checked before the run."""

import pytest

from jaxlp import cliutil


def test_parser_errors_are_one_line_and_exit_2(capsys):
    p = cliutil.Parser(prog="prog")
    p.add_argument("--n", type=int)
    with pytest.raises(SystemExit) as exc:
        p.parse_args(["--n", "x"])
    assert exc.value.code == cliutil.EXIT_USAGE == 2
    err = capsys.readouterr().err
    assert err.startswith("prog: error: ") and err.count("\n") == 1


def test_refuse_and_interrupted_fold_the_message_to_one_line(capsys):
    assert cliutil.refuse("prog", "bad\n  value") == 2
    assert cliutil.interrupted("prog", "after 3 of 9 chunks;\nrerun with --resume") == 130
    assert capsys.readouterr().err == ("prog: error: bad value\n"
                                       "prog: interrupted after 3 of 9 chunks; rerun with --resume\n")


def test_output_file_checks(tmp_path):
    cliutil.check_output_file("--plot", tmp_path / "a.png", (".png",))
    cliutil.check_output_file("--out", None)
    with pytest.raises(ValueError, match="--plot must end in one of .png"):
        cliutil.check_output_file("--plot", tmp_path / "a.txt", (".png",))
    with pytest.raises(ValueError, match="names a folder"):
        cliutil.check_output_file("--out", tmp_path)
    with pytest.raises(ValueError, match="--out .*does not exist or is not writable"):
        cliutil.check_output_file("--out", tmp_path / "missing" / "a.json")
    with pytest.raises(ValueError, match="/proc/x.png"):
        cliutil.check_output_file("--plot", "/proc/x.png", (".png",))  # root passes the mode bits: tried, not read
    assert list(tmp_path.iterdir()) == []  # the probes leave nothing behind


def test_a_finished_result_is_not_replaced_without_force(tmp_path):
    cliutil.check_no_overwrite("--out", tmp_path, ("tuned.json",), force=False)  # nothing there yet
    (tmp_path / "tuned.json").write_text("{}")
    with pytest.raises(ValueError, match="already holds tuned.json: use --force"):
        cliutil.check_no_overwrite("--out", tmp_path, ("tuned.json", "loss.png"), force=False)
    cliutil.check_no_overwrite("--out", tmp_path, ("tuned.json",), force=True)


def test_output_dir_checks(tmp_path):
    cliutil.check_output_dir("--out", tmp_path / "new" / "deeper")  # made later, under a writable folder
    (tmp_path / "f").write_text("x")
    with pytest.raises(ValueError, match="--out .*is a file, not a folder"):
        cliutil.check_output_dir("--out", tmp_path / "f")
    with pytest.raises(ValueError, match="cannot write into '/proc'"):
        cliutil.check_output_dir("--out", "/proc/x")
    assert [p.name for p in tmp_path.iterdir()] == ["f"]
