"""Execute notebooks/05_tuning_and_regions.ipynb and check what it prints and draws."""

from pathlib import Path

import nbformat
from nbclient import NotebookClient

NOTEBOOK = Path(__file__).resolve().parents[2] / "notebooks" / "05_tuning_and_regions.ipynb"


def test_notebook_05_runs_and_shows_tuning_and_regions():
    nb = nbformat.read(NOTEBOOK, as_version=4)
    NotebookClient(nb, timeout=120, kernel_name="python3",
                   resources={"metadata": {"path": str(NOTEBOOK.parent)}}).execute()
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    text = "".join(o.get("text", "") for o in outputs)
    assert "training loss" in text and "seed  :" in text and "tuned :" in text
    assert "same cell at every timing: True" in text
    assert "MJX seed  :" in text and "MJX tuned :" in text and "MJX tuning: sway" in text
    images = sum(1 for o in outputs if "image/png" in o.get("data", {}))
    assert images == 4  # the loss curve, the held-out 3LP and MJX maps, the regions
