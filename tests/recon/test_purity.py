"""The layout rules: recon is pure, only recon.io touches pydicom, highdicom, vtk and Dask,
no module is too long."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MAX_LINES = 700


def _py_files(*folders: str) -> list[Path]:
    return sorted(p for folder in folders for p in (ROOT / folder).rglob("*.py"))


def _rel(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


# Libraries that touch files, DICOM or a cluster: imported in recon/io/ only.
_EDGE_ONLY = ("pydicom", "highdicom", "vtk", "vtkmodules", "dask", "distributed")


def test_importing_the_pipeline_loads_no_edge_library_nor_viser() -> None:
    code = (
        "import recon.pipeline, sys; "
        f"loaded = {{*{_EDGE_ONLY!r}, 'viser'}} & set(sys.modules); assert not loaded, loaded"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr


def _imports(tree: ast.AST) -> list[tuple[str, bool]]:
    """(top-level package, inside a function) of every import in a module."""
    found: list[tuple[str, bool]] = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef))
            if isinstance(child, ast.Import):
                found.extend((alias.name.split(".")[0], in_function) for alias in child.names)
            elif isinstance(child, ast.ImportFrom) and child.module and child.level == 0:
                found.append((child.module.split(".")[0], in_function))
            visit(child, inner)

    visit(tree, False)
    return found


# Modules of recon/ that may import the viewer, inside a function only (the
# `view` command, and a bench that drives the viewer).
_VIEWER_ALLOWED = ("recon/cli.py", "recon/bench/")


@pytest.mark.parametrize("path", _py_files("recon"), ids=_rel)
def test_edge_libraries_only_in_recon_io_and_no_viewer_in_recon(path: Path) -> None:
    rel = _rel(path)
    for package, in_function in _imports(ast.parse(path.read_text(encoding="utf-8"))):
        if package in _EDGE_ONLY:
            assert rel.startswith("recon/io/"), f"{rel} imports {package} outside recon/io/"
        if package in ("viser", "viewer_app"):
            allowed = package == "viewer_app" and rel.startswith(_VIEWER_ALLOWED)
            assert allowed and in_function, f"{rel} imports {package}"


@pytest.mark.parametrize("path", _py_files("recon", "viewer_app"), ids=_rel)
def test_no_module_is_over_700_lines(path: Path) -> None:
    n_lines = len(path.read_text(encoding="utf-8").splitlines())
    assert n_lines <= MAX_LINES, f"{_rel(path)} has {n_lines} lines (at most {MAX_LINES})"
