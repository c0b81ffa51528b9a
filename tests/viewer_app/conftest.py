"""Fixtures of the viewer tests: the bundled demo case and a running ViewerApp."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from recon.io import demo_paths
from viewer_app import ViewerApp

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def artifacts_dir() -> Path:
    """test-artifacts/viewer/ (git-ignored): screenshots and measured figures."""
    path = REPO / "test-artifacts" / "viewer"
    path.mkdir(parents=True, exist_ok=True)
    return path


@pytest.fixture(scope="session")
def demo_case() -> dict[str, Path]:
    """assets/demo/a.dcm, b.dcm, seeds.json (the case `coronary3d view` opens by default)."""
    paths = {k: v for k, v in demo_paths().items() if k in ("a", "b", "seeds")}
    missing = [str(p) for p in paths.values() if not p.is_file()]
    assert not missing, f"demo case missing: {', '.join(missing)}"
    return paths


@pytest.fixture()
def app(demo_case: dict[str, Path], tmp_path: Path) -> Iterator[ViewerApp]:
    """The viewer on the demo case, served on 127.0.0.1 at a free port, autosaving in tmp_path."""
    viewer = ViewerApp(
        str(demo_case["a"]),
        str(demo_case["b"]),
        str(demo_case["seeds"]),
        host="127.0.0.1",
        port=0,
        autosave_path=tmp_path / "seeds.autosave.json",
        out_dir=tmp_path,
    )
    try:
        yield viewer
    finally:
        viewer.stop()
