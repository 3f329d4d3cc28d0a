"""Every notebook runs headless in its quick mode and stays thin."""

import ast
import json
from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).parents[1] / "notebooks").glob("[0-9][0-9]_*.ipynb"))


def test_there_are_notebooks():
    assert NOTEBOOKS


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_thin_and_committed_without_outputs(path):
    nb = json.loads(path.read_text())
    code = [c for c in nb["cells"] if c["cell_type"] == "code"]
    assert all(not c.get("outputs") and c.get("execution_count") is None for c in code)
    first = code[0]
    assert "parameters" in first["metadata"].get("tags", [])
    for node in ast.parse("".join(first["source"])).body:
        assert isinstance(node, ast.Assign)
        ast.literal_eval(node.value)  # raises unless the value is a literal
    assert "quick" in "".join(first["source"])
    for cell in code:
        tree = ast.parse("".join(cell["source"]))
        defs = [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef | ast.ClassDef)]
        assert not defs, f"{path.name}: move definitions into volec"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_agrees_with_its_reviewed_source(path):
    """Each notebook has a jupytext twin, notebooks/NN_name.py, that is the source people
    edit and review; `make notebooks` brings the .ipynb up to date with it."""
    jupytext = pytest.importorskip("jupytext")
    source = path.with_suffix(".py")
    assert source.exists(), f"{path.name} has no paired {source.name}"

    def cells(nb) -> list[tuple[str, str, list[str]]]:
        return [(c.cell_type, c.source.strip(), sorted(c.metadata.get("tags", [])))
                for c in nb.cells]

    assert cells(jupytext.read(source)) == cells(jupytext.read(path)), \
        f"{path.name} differs from {source.name}: run `make notebooks`"


@pytest.fixture(scope="session")
def notebook_data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One data folder for every notebook of the session: like `make paper`, a later notebook
    reuses what an earlier one computed (05 reads 04's cached results)."""
    return tmp_path_factory.mktemp("notebook-data")


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs_in_quick_mode(path, tmp_path, notebook_data, monkeypatch):
    papermill = pytest.importorskip("papermill")
    from jupyter_client.kernelspec import KernelSpecManager

    monkeypatch.setenv("VOLEC_FIGURES_DIR", str(tmp_path / "figures"))
    monkeypatch.setenv("VOLEC_DATA_DIR", str(notebook_data))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    kernel = "volec" if "volec" in KernelSpecManager().find_kernel_specs() else "python3"
    papermill.execute_notebook(
        str(path), str(tmp_path / path.name), parameters={"quick": True},
        kernel_name=kernel, cwd=str(path.parent), progress_bar=False,
    )
    written = list((tmp_path / "figures").iterdir())
    assert written, "the notebook wrote no figure or table"
    # `make paper` exports each executed notebook to HTML, pictures inside it
    from nbconvert import HTMLExporter

    page, _ = HTMLExporter(embed_images=True).from_filename(str(tmp_path / path.name))
    assert "<html" in page and "Traceback" not in page
