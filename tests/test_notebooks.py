"""Every notebook runs top to bottom (marked: run by .ci/run, not by the default test run)."""

import ast
import importlib
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("[0-9][0-9]_*.py"))


@pytest.mark.notebooks
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, monkeypatch):
    jupytext = pytest.importorskip("jupytext")
    nbclient = pytest.importorskip("nbclient")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = jupytext.read(path)
    # run from notebooks/, as a reader would; the notebooks write their outputs to temporary directories
    client = nbclient.NotebookClient(nb, timeout=900, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}})
    client.execute()  # a failing cell raises nbclient's CellExecutionError, naming the cell and its traceback


def _package_imports(tree: ast.AST):
    """``(module, names)`` of every ``from tire_learning_env... import names`` in ``tree``."""
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "tire_learning_env":
            yield node.module, [alias.name for alias in node.names]


def _has_name(module, name: str) -> bool:
    """``module`` has attribute ``name`` or, being a package, a submodule ``name``."""
    if hasattr(module, name):
        return True
    return hasattr(module, "__path__") and importlib.util.find_spec(f"{module.__name__}.{name}") is not None


def test_notebooks_are_percent_scripts_whose_cells_compile_and_whose_package_imports_exist():
    """Fast stand-in for executing them: jupytext reads each, every code cell compiles, every name
    imported from the package exists (a moved or renamed function breaks this), and no ``.ipynb``
    (which could store outputs) sits beside them."""
    jupytext = pytest.importorskip("jupytext")
    assert len(NOTEBOOKS) >= 3
    assert not sorted((ROOT / "notebooks").glob("*.ipynb")), "notebooks are jupytext percent scripts; outputs are not stored"
    for path in NOTEBOOKS:
        nb = jupytext.read(path)
        assert nb.metadata["jupytext"]["text_representation"]["format_name"] == "percent", path.name
        code = [cell.source for cell in nb.cells if cell.cell_type == "code"]
        assert code and any(cell.cell_type == "markdown" for cell in nb.cells), path.name
        for k, source in enumerate(code):
            tree = ast.parse(source, filename=f"{path.name} code cell {k}")
            for module, names in _package_imports(tree):
                imported = importlib.import_module(module)
                missing = [n for n in names if not _has_name(imported, n)]
                assert not missing, f"{path.name} imports {missing} from {module}, which has no such name"
