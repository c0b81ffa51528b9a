"""recon.io.overrides: geometry overrides and their JSON."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from recon.errors import LoadError
from recon.io.overrides import GeometryOverrides


def test_overrides_from_json(tmp_path: Path) -> None:
    js = tmp_path / "ov.json"
    js.write_text(json.dumps({"sid_mm": 1000, "pixel_spacing_mm": [0.2, 0.3]}))
    ov = GeometryOverrides.from_json(js)
    assert ov.sid_mm == 1000.0 and ov.pixel_spacing_mm == (0.2, 0.3)
    assert ov.alpha_deg is None and ov.sod_mm is None
    js.write_text(json.dumps({"sid_mm": -5}))
    with pytest.raises(LoadError, match=r"ov\.json: sid_mm = -5 mm is outside .*700 to 1300 mm"):
        GeometryOverrides.from_json(js)
    with pytest.raises(LoadError, match="pixel_spacing_mm"):
        GeometryOverrides(pixel_spacing_mm=(0.2, 0.0))  # type: ignore[arg-type]
