"""Execute notebooks/03_walking_and_pushes.ipynb with short walks and check what it prints.

The notebook's walks are 4 s here (``NB03_SECONDS``); their compiled walk is
the same program as the 4 s run of ``tests/mjx_coman/test_walk_cli.py``, and
both subprocesses share JAX's persistent compilation cache in the session's
temporary directory, so whichever runs second skips the compilation. The execution (about 50 s after that
compilation) is a slow test: the default suite took 934 s of pytest on 2 cores with it (fresh clone, 2761ebc).
"""

import re
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOK = Path(__file__).resolve().parents[2] / "notebooks" / "03_walking_and_pushes.ipynb"
SECONDS = "4"  # keep equal to the CLI test's --seconds (shared compilation)


@pytest.mark.slow
def test_notebook_03_runs_and_walks(tmp_path, tmp_path_factory, monkeypatch):
    monkeypatch.setenv("NB03_SECONDS", SECONDS)
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "jax_compile_cache"))
    nb = nbformat.read(NOTEBOOK, as_version=4)
    NotebookClient(nb, timeout=240, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    text = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if o.get("output_type") == "error"]
    assert not errors
    # the closed-loop in-place walk stands the 4 s and lands a foot every 0.4 s after its start-up phase
    line = re.search(r"^closed loop +fell=(\w+) +touchdowns= *(\d+)", text, re.M)
    assert line and line.group(1) == "False" and int(line.group(2)) >= 8, text
    assert "footstep spread: sagittal" in text
    images = sum(1 for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if "image/png" in o.get("data", {}))
    assert images == 3
