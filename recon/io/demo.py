"""The bundled demo case: two phantom XA files and their seeds."""

from __future__ import annotations

from pathlib import Path

__all__ = ["demo_dir", "demo_paths"]


def demo_dir() -> Path:
    """The folder that holds the demo's a.dcm, b.dcm, seeds.json and truth.json."""
    return Path(__file__).resolve().parents[2] / "assets" / "demo"


def demo_paths() -> dict[str, Path]:
    """The demo's files by role: ``{"a": ..., "b": ..., "seeds": ..., "truth": ...}``."""
    d = demo_dir()
    names = {"a": "a.dcm", "b": "b.dcm", "seeds": "seeds.json", "truth": "truth.json"}
    return {role: d / name for role, name in names.items()}
