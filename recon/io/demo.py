"""The bundled demo case: two phantom XA files, their seeds and the truth.

The files live in the source tree under ``assets/demo`` and ship inside the
wheel as the data package ``recon.io.demo_case`` (see pyproject.toml), so a
plain ``pip install`` runs ``coronary3d reconstruct --demo`` and
``coronary3d view`` with no files.
"""

from __future__ import annotations

from pathlib import Path

from recon.errors import LoadError

__all__ = ["demo_dir", "demo_paths"]

_CANDIDATES = (
    Path(__file__).resolve().parent / "demo_case",  # installed from a wheel
    Path(__file__).resolve().parents[2] / "assets" / "demo",  # source tree, editable install
)


def demo_dir() -> Path:
    """The folder that holds the demo's a.dcm, b.dcm, seeds.json and truth.json."""
    for folder in _CANDIDATES:
        if (folder / "a.dcm").is_file():
            return folder
    raise LoadError(
        f"the demo case is not installed (looked in {', '.join(str(c) for c in _CANDIDATES)})"
    )


def demo_paths() -> dict[str, Path]:
    """The demo's files by role: ``{"a": ..., "b": ..., "seeds": ..., "truth": ...}``."""
    d = demo_dir()
    names = {"a": "a.dcm", "b": "b.dcm", "seeds": "seeds.json", "truth": "truth.json"}
    return {role: d / name for role, name in names.items()}
