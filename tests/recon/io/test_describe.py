"""recon.io.describe: the `coronary3d info` facts and text."""

from __future__ import annotations

import json
from pathlib import Path

from recon.io.describe import describe_file, format_description

DATA = Path(__file__).resolve().parents[2] / "data"
IM7 = DATA / "IM7.dcm"
RCA = DATA / "rca-cine-ecg.dcm"


def test_describe_reports_missing_geometry_without_raising() -> None:
    desc = describe_file(RCA)
    assert desc["n_frames"] == 96 and desc["frame_time_ms"] == 33.0
    assert desc["sop_class_name"] == "X-Ray Angiographic Image Storage"
    assert desc["geometry"]["alpha_deg"] == -32.0
    assert desc["geometry"]["sid_mm"] is None and desc["geometry"]["pixel_spacing_mm"] is None
    assert len(desc["missing"]) == 3
    assert desc["r_wave_pointer"] == [20, 53, 77]
    assert "patient_name" not in desc
    text = format_description(desc)
    assert "SID             missing" in text
    assert "R Wave Pointer 20, 53, 77" in text
    assert "Rubo" not in text
    shown = describe_file(RCA, show_patient=True)
    assert "Rubo" in format_description(shown)
    desc7 = describe_file(IM7)
    assert desc7["geometry"]["sid_mm"] == 976.0 and desc7["missing"] == []
    assert desc7["frame_index"] == 4
    json.dumps(desc7)  # JSON-ready
