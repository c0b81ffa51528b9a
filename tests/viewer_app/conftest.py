"""Fixtures of the viewer tests: the bundled demo case, a running ViewerApp and a
``coronary3d view --port 0`` process."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
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


@dataclass
class ViewProcess:
    """A ``coronary3d view --port 0`` process and the first line it printed."""

    proc: subprocess.Popen
    line: str  # "coronary3d viewer: http://127.0.0.1:PORT/?token=..." when it started
    url: str | None  # the address with its token, None when the line has none
    port: int | None
    stderr: str | None = field(default=None, init=False)

    def stop(self) -> str:
        """SIGTERM, wait, and return what the process wrote on stderr (once)."""
        if self.stderr is None:
            if self.proc.poll() is None:
                self.proc.send_signal(signal.SIGTERM)
            _, self.stderr = self.proc.communicate(timeout=30)
        return self.stderr


@pytest.fixture()
def start_view(tmp_path: Path) -> Iterator[Callable[..., ViewProcess]]:
    """Start ``coronary3d view --port 0`` (the demo) in tmp_path, its cache in
    ``cache_dir`` (default tmp_path/cache); every process started is stopped after the
    test."""
    started: list[ViewProcess] = []

    def start(cache_dir: Path | None = None) -> ViewProcess:
        env = {k: v for k, v in os.environ.items() if k != "CORONARY3D_DEBUG"}
        env["XDG_CACHE_HOME"] = str(cache_dir or tmp_path / "cache")
        proc = subprocess.Popen([sys.executable, "-m", "recon.cli", "view", "--port", "0"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env=env, cwd=tmp_path)
        assert proc.stdout is not None
        line = proc.stdout.readline()
        found = re.search(r"coronary3d viewer: (http://127\.0\.0\.1:(\d+)/\?token=[\w-]+)",
                          line)
        view = ViewProcess(proc, line, found[1] if found else None,
                           int(found[2]) if found else None)
        started.append(view)
        return view

    yield start
    for view in started:
        view.stop()
