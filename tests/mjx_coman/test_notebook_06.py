"""notebooks/06_footstep_mpc.ipynb: every experiment it shows is one the studies plan for footstep-mpc at the small
size (default suite); executed at the small size (two 1.2 s walks per experiment, one compilation shared with
tests/mjx_coman/studies/test_studies_cli.py through JAX's persistent cache; the rough-ground experiment, a scene and
compilation of its own, is skipped there and run by the last test). The execution is marked slow: 148 s of the
default suite's 1146 s on 2 cores, which put it past 15 minutes (`-m slow` runs it)."""

import re
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOK = Path(__file__).resolve().parents[2] / "notebooks" / "06_footstep_mpc.ipynb"


def test_every_experiment_the_notebook_shows_is_planned_for_footstep_mpc():
    from mjx_coman import studies

    code = "\n".join(c.source for c in nbformat.read(NOTEBOOK, as_version=4).cells if c.cell_type == "code")
    shown = re.findall(r'^show\("([a-z-]+)"\)$', code, re.M)
    assert len(shown) == 9 and len(set(shown)) == 9, shown
    for name in shown:
        assert studies.plan(name, "footstep-mpc", "small").rows, name  # raises for an unknown experiment


@pytest.mark.slow
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
