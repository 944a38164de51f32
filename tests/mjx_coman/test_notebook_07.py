"""Execute notebooks/07_straight_leg.ipynb at the small size (two 1.2 s walks per experiment and controller:
every flat one shares one compilation of the straight-leg family; the stairs, a scene and compilation of their
own, are skipped here)."""

import re
from pathlib import Path

import nbformat
from nbclient import NotebookClient

NOTEBOOK = Path(__file__).resolve().parents[2] / "notebooks" / "07_straight_leg.ipynb"


def test_notebook_07_runs_every_flat_experiment_of_each_variant(tmp_path, monkeypatch):
    monkeypatch.setenv("NB07_SIZE", "small")
    monkeypatch.setenv("NB07_SKIP", "stairs")
    nb = nbformat.read(NOTEBOOK, as_version=4)
    NotebookClient(nb, timeout=900, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    text = "".join(o.get("text", "") for o in outputs)
    runs = [("flat", "straight-leg"), ("flat", "bent-knee"), ("toe-off", "straight-leg"),
            ("toe-off", "straight-leg-no-toe-off"), ("mid-swing-push", "straight-leg"),
            ("mid-swing-push", "straight-leg-step-adjust")]
    for name, ctrl in runs:
        assert re.search(rf"^{name} {ctrl}: 2 walks of 1\.2 s, [0-2] fell$", text, re.M), (name, ctrl, text)
    # unpushed, every variant stands its start (ground truth)
    assert re.search(r"^flat straight-leg: 2 walks of 1\.2 s, 0 fell$", text, re.M)
    assert re.search(r"^toe-off straight-leg-no-toe-off: 2 walks of 1\.2 s, 0 fell$", text, re.M)
    assert "stairs straight-leg: skipped" in text
    assert sum("image/png" in o.get("data", {}) for o in outputs) == len(runs)
    assert not list(tmp_path.glob("data/07/*.json"))  # small runs store nothing
