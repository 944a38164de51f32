"""notebooks/08_side_by_side.ipynb: its small run asks for a comparison the command line accepts (default suite),
and executed at the small size: a live comparison of time projection and footstep MPC on a tiny grid
(2 directions x 1 phase x 1 impulse, twice, 4-step walks), its scorecard and combined figure, the stored tuning
runs, and one rendered walk. The compare run and the walk have the shapes of tests/sweeps/test_scorecard.py's
agreement test: one compilation each in the session's cache. The execution is marked slow: about 155 s on 2
cores, with which the default suite took 914 s of pytest, 16 min in all, in a fresh clone (`-m slow` runs it)."""

import json
import re
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

from mjx_coman import controllers as registry
from sweeps import cli

NOTEBOOK = Path(__file__).resolve().parents[2] / "notebooks" / "08_side_by_side.ipynb"


def test_the_notebooks_small_run_is_a_compare_the_command_line_accepts(tmp_path):
    code = "\n".join(c.source for c in nbformat.read(NOTEBOOK, as_version=4).cells if c.cell_type == "code")
    names = eval(re.search(r'CONTROLLERS = (\[.*?\]) if SIZE == "small"', code).group(1))
    for name in names:
        registry.get(name)  # registered
    argv = eval(re.search(r"argv = (\[.*?\])\n", code, re.S).group(1), {"CONTROLLERS": names, "OUT": tmp_path})
    args = cli.build_parser().parse_args(argv)
    assert args.command == "compare" and list(args.controllers) == names
    assert code.count("walk.main(") == 1 and '"--video"' in code


@pytest.mark.slow
def test_notebook_08_compares_both_controllers_and_renders_a_walk(tmp_path, monkeypatch):
    monkeypatch.setenv("NB08_SIZE", "small")
    nb = nbformat.read(NOTEBOOK, as_version=4)
    NotebookClient(nb, timeout=900, kernel_name="python3",
                   resources={"metadata": {"path": str(NOTEBOOK.parent)}}).execute()
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    text = "".join(o.get("text", "") for o in outputs)
    assert "2 scorecard rows: time-projection, footstep-mpc" in text
    for ctrl in ("time-projection", "footstep-mpc"):
        line = re.search(rf"^ *{ctrl}: (\d+)% recovered, (\d+) fell, (\d+) ended by a failed solve, (\d+) non-finite$",
                         text, re.M)
        assert line, text
        fell, failed, nan = (int(line.group(k)) for k in (2, 3, 4))
        assert fell + failed + nan <= 4  # 4 walks each (2 directions, twice)
        assert ctrl == "footstep-mpc" or failed == 0  # time projection solves nothing that can fail
    assert re.search(r"^direction +forward: most recovered [03] N s by ", text, re.M)
    md = [o["data"]["text/markdown"] for o in outputs if "text/markdown" in o.get("data", {})]
    assert len(md) == 1 and md[0].count("\n| ") == 3  # the scorecard: the header and one row per controller
    images = [o for o in outputs if "image/png" in o.get("data", {}) or "image/gif" in o.get("data", {})]
    assert len(images) == 2  # the combined figure and the rendered walk
    assert "walk-time-projection" in text
    stored = sorted((NOTEBOOK.parent / "data" / "08").glob("tune-*/holdout.json"))
    for path in stored:  # each stored tuning run reports its paired held-out comparison
        assert json.loads(path.read_text())["paired"]["pairs"] >= 200
        assert "paired over" in text
