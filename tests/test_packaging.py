"""The wheel ships every package of the project and the demo case."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _setuptools_table() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"][
        "setuptools"
    ]


def test_every_package_is_listed() -> None:
    listed = set(_setuptools_table()["packages"])
    on_disk = {
        ".".join(p.parent.relative_to(ROOT).parts)
        for top in ("recon", "viewer_app")
        for p in (ROOT / top).rglob("__init__.py")
    }
    assert on_disk <= listed, f"packages missing from pyproject.toml: {sorted(on_disk - listed)}"


def test_demo_case_is_package_data() -> None:
    table = _setuptools_table()
    folder = ROOT / table["package-dir"]["recon.io.demo_case"]
    patterns = table["package-data"]["recon.io.demo_case"]
    shipped = {p.name for pattern in patterns for p in folder.glob(pattern)}
    assert {"a.dcm", "b.dcm", "seeds.json", "truth.json"} <= shipped
