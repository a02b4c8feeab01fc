"""docs/quickstart.ipynb, executed top to bottom as Jupyter would run it (nbclient, a Python 3
kernel): a notebook that no longer runs fails here, so the example cannot rot."""

import os
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

nbclient = pytest.importorskip("nbclient")
nbformat = pytest.importorskip("nbformat")

REPO = Path(__file__).resolve().parents[1]


def test_the_quickstart_notebook_runs_top_to_bottom(tmp_path, monkeypatch):
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    monkeypatch.setenv("TMPDIR", str(tmp_path))  # the notebook writes only into a temporary directory
    for name in [name for name in os.environ if name.startswith(("TF_", "DQFD_", "KERAS_"))]:
        monkeypatch.delenv(name)  # a user's kernel: the notebook's first cell configures it (runtime.configure)
    notebook = nbformat.read(REPO / "docs" / "quickstart.ipynb", as_version=4)
    docs_before = sorted(p.name for p in (REPO / "docs").iterdir())
    nbclient.NotebookClient(
        notebook, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}
    ).execute()
    printed, shown = (
        "".join(
            output.get("text", "")
            for cell in notebook.cells
            if cell.cell_type == "code"
            for output in cell.outputs
            if output.get("name") == stream
        )
        for stream in ("stdout", "stderr")
    )
    assert printed.count("greedy episodes") == 3  # CartPole, the user's env, CartPole loaded and trained more
    assert "python callable walk_right" in printed and "demonstrations from minari:cartpole/push-v0" in printed
    assert "episode 5: return" in printed and "episode 6:" not in printed  # the callback stopped training
    assert "'complete.json'" in printed and "'q_network.keras'" in printed
    assert "DqfdWarning" not in shown  # configure() came before TensorFlow loaded
    assert "3000/3000" in shown  # learn(progress_bar=True) in Jupyter: tqdm.auto's bar (text without ipywidgets)
    [work] = tmp_path.glob("dqfd-quickstart-*")
    assert (work / "cartpole" / "complete.json").is_file() and (work / "minari" / "cartpole" / "push-v0").is_dir()
    assert sorted(p.name for p in (REPO / "docs").iterdir()) == docs_before
