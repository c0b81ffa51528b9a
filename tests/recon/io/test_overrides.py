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


def test_per_file_overrides_win_over_the_flags_for_every_file(tmp_path: Path) -> None:
    from recon.io.overrides import per_file_overrides

    js = tmp_path / "a.json"
    js.write_text(json.dumps({"sid_mm": 1000}))
    common = GeometryOverrides(sid_mm=900.0, sod_mm=700.0, source="command line")
    ov = per_file_overrides(common, js)
    assert ov.sid_mm == 1000.0 and ov.sod_mm == 700.0
    assert per_file_overrides(common, None) is common
    assert per_file_overrides(None, None) is None


def test_typed_geometry_keeps_header_values_unless_changed() -> None:
    from recon.io.overrides import header_replacements, overrides_from_entries

    header = {"sid_mm": 976.0, "sod_mm": None, "pixel_spacing_mm": [0.39, 0.39]}
    ov, replaced = overrides_from_entries(
        {"sid_mm": "976", "sod_mm": "720", "pixel_spacing_mm": ""}, header, "Geometry A")
    assert ov is not None and ov.values() == {"sod_mm": 720.0} and replaced == []
    ov, replaced = overrides_from_entries({"sid_mm": "1000"}, header, "Geometry A")
    assert ov.sid_mm == 1000.0 and replaced == ["SID 1000 replaces the header's 976"]
    assert overrides_from_entries({"sid_mm": ""}, header, "Geometry A") == (None, [])
    with pytest.raises(LoadError, match="Geometry A: SID 'abc' is not a number"):
        overrides_from_entries({"sid_mm": "abc"}, header, "Geometry A")
    with pytest.raises(LoadError, match="Geometry A"):
        overrides_from_entries({"sid_mm": "5"}, header, "Geometry A")  # out of range
    notes = ("sid_mm 1000 from x.json (header says 976)", "SOD from magnification")
    assert header_replacements(notes) == [notes[0]]
