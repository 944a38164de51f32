"""Execute notebooks/04_basin_maps.ipynb (3LP part; the MJX part is switched off with COMAN_NB_MJX=0)."""

from pathlib import Path

import nbformat
from nbclient import NotebookClient

NOTEBOOK = Path(__file__).resolve().parents[2] / "notebooks" / "04_basin_maps.ipynb"


def test_notebook_04_runs_and_shows_time_projection_beating_dlqr_late(tmp_path, monkeypatch):
    monkeypatch.setenv("COMAN_NB_MJX", "0")  # the MJX maps take minutes on 2 CPU cores
    nb = nbformat.read(NOTEBOOK, as_version=4)
    NotebookClient(nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    text = "".join(o.get("text", "") for o in outputs)
    assert "at every phase >= 0.5: True" in text
    assert "largest recovered forward impulse" in text and "MJX part skipped" in text
    assert sum(1 for o in outputs if "image/png" in o.get("data", {})) == 1  # the three 3LP maps, one figure
