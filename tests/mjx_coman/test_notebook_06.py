"""Execute notebooks/06_footstep_mpc.ipynb at the small size (two 1.2 s walks per experiment, one compilation
shared with tests/mjx_coman/studies/test_studies_cli.py through JAX's persistent cache; the rough-ground
experiment, a scene and compilation of its own, is skipped here and run by the slow test below)."""

import re
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOK = Path(__file__).resolve().parents[2] / "notebooks" / "06_footstep_mpc.ipynb"


def test_notebook_06_runs_every_flat_experiment(tmp_path, tmp_path_factory, monkeypatch):
    monkeypatch.setenv("NB06_SIZE", "small")
    monkeypatch.setenv("NB06_SKIP", "terrain")
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "jax_compile_cache"))
    nb = nbformat.read(NOTEBOOK, as_version=4)
    NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    text = "".join(o.get("text", "") for o in outputs)
    names = ("speeds", "steer", "push", "model-error", "slope", "noise", "delay", "actuators")
    for name in names:
        assert re.search(rf"^{name}: 2 walks of 1\.2 s, [0-2] fell$", text, re.M), (name, text)
    # the controller stands its start and first step, in place and at 0.2 m/s (ground truth)
    assert re.search(r"^speeds: 2 walks of 1\.2 s, 0 fell$", text, re.M)
    assert "terrain: skipped" in text
    assert sum("image/png" in o.get("data", {}) for o in outputs) == len(names)
    assert not list(tmp_path.glob("data/06/*.json"))  # small runs store nothing


@pytest.mark.slow
def test_rough_ground_small_walk_runs():
    from mjx_coman import studies

    result, rows = studies.run("terrain", "footstep-mpc", "small")
    assert result["terrains"] == 1 and rows[0]["label"]["terrain"] == "rough:5:0"
    assert isinstance(result["rows"][0]["fell"], bool)
