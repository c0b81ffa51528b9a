"""recon.io.angiogram: loading real and synthetic files, geometry overrides and fallbacks."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy import ndimage

from recon.errors import LoadError
from recon.io.angiogram import load_angiogram
from recon.io.describe import describe_file
from recon.io.dicom_write import _write_test_dicom
from recon.io.frames import vessel_contrast_scores
from recon.io.overrides import GeometryOverrides

DATA = Path(__file__).resolve().parents[2] / "data"
IM7 = DATA / "IM7.dcm"
IM8 = DATA / "IM8.dcm"
RCA = DATA / "rca-cine-ecg.dcm"


@pytest.mark.parametrize(
    "path, alpha, beta, n_frames",
    [(IM7, -29.3, 25.5, 9), (IM8, 30.7, 23.6, 8)],
)
def test_real_phantom_geometry_and_representative_frame(
    path: Path, alpha: float, beta: float, n_frames: int
) -> None:
    ang = load_angiogram(path)
    g = ang.geometry
    assert (g.alpha_deg, g.beta_deg) == pytest.approx((alpha, beta), abs=1e-9)
    assert (g.sid_mm, g.sod_mm) == (976.0, 720.0)
    assert g.pixel_spacing_mm == (0.390625, 0.390625)
    assert (g.rows, g.cols) == (512, 512)
    assert ang.image.shape == (512, 512) and ang.image.dtype == np.float32
    assert ang.n_frames == n_frames
    assert ang.frames is not None and ang.frames.shape == (n_frames, 512, 512)
    # RepresentativeFrameNumber 5 is 1-based: frame index 4
    assert ang.frame_index == 4
    assert ang.frame_reason == "RepresentativeFrameNumber 5"
    np.testing.assert_array_equal(ang.image, ang.frames[4])
    assert ang.geometry_notes == ()
    assert ang.info["transfer_syntax"] == "1.2.840.10008.1.2.4.70"  # JPEG Lossless decoded
    assert ang.info["bits_stored"] == 8


def test_im7_vessels_are_dark() -> None:
    """The contrast-filled tubes are thin dark structures: the black top-hat
    (dark details) is much stronger than the white top-hat (bright details)."""
    image = load_angiogram(IM7).image[20:490, 20:490]  # inside the collimator
    black = ndimage.grey_closing(image, size=(15, 15)) - image
    white = image - ndimage.grey_opening(image, size=(15, 15))
    assert np.percentile(black, 99) > 1.8 * np.percentile(white, 99)


def test_explicit_frame_and_with_frame() -> None:
    ang = load_angiogram(IM7, frame=8)
    assert ang.frame_index == 8 and ang.frame_reason == "explicit"
    other = ang.with_frame(0)
    assert other.frame_index == 0 and other.frame_reason == "explicit"
    np.testing.assert_array_equal(other.image, ang.frames[0])
    assert other.geometry == ang.geometry
    for bad in (9, -1):
        with pytest.raises(LoadError, match=r"IM7\.dcm: frame .* out of range.*9 frames"):
            load_angiogram(IM7, frame=bad)
    with pytest.raises(LoadError, match="out of range"):
        ang.with_frame(9)


def test_rca_missing_distances_name_the_tag() -> None:
    with pytest.raises(LoadError) as err:
        load_angiogram(RCA)
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith(f"{RCA}: ")
    assert "rca-cine-ecg.dcm" in message
    assert "DistanceSourceToDetector (0018,1110) is missing" in message
    assert "--sid-mm" in message
    assert "DistanceSourceToPatient" in message and "ImagerPixelSpacing" in message


def test_rca_loads_with_overrides_at_an_r_wave() -> None:
    overrides = GeometryOverrides(sid_mm=1000.0, sod_mm=750.0, pixel_spacing_mm=(0.3, 0.3))
    ang = load_angiogram(RCA, overrides=overrides)
    assert ang.n_frames == 96 and ang.frames is not None and ang.frames.shape[0] == 96
    assert ang.frame_time_ms == 33.0
    assert ang.info["r_wave_pointer"] == [20, 53, 77]
    assert ang.info["r_wave_frames"] == [19, 52, 76]
    assert ang.info["transfer_syntax"] == "1.2.840.10008.1.2.4.50"  # JPEG Baseline decoded
    g = ang.geometry
    assert (g.alpha_deg, g.beta_deg) == (-32.0, 2.0)
    assert (g.sid_mm, g.sod_mm, g.pixel_spacing_mm) == (1000.0, 750.0, (0.3, 0.3))
    assert any(note.startswith("SID 1000 from override") for note in ang.geometry_notes)
    # an end-diastolic frame, the best-opacified one: frame 19 is early in the
    # injection (little contrast), 52 and 76 are filled
    assert ang.frame_index in (52, 76)
    assert ang.frame_reason.startswith("end-diastolic: R wave at frame")
    scores = vessel_contrast_scores(ang.frames[[19, 52, 76]])
    assert scores[0] < scores[1] and scores[0] < scores[2]


def test_rca_geometry_json_fills_the_gaps(tmp_path: Path) -> None:
    json_path = tmp_path / "rca.json"
    json_path.write_text(json.dumps({"sid_mm": 1100, "sod_mm": 800, "pixel_spacing_mm": 0.25}))
    ang = load_angiogram(RCA, geometry_json=json_path, frame=10)
    assert (ang.geometry.sid_mm, ang.geometry.sod_mm) == (1100.0, 800.0)
    assert ang.geometry.pixel_spacing_mm == (0.25, 0.25)
    assert any("from rca.json" in note for note in ang.geometry_notes)
    # an explicit override wins over the JSON
    ang = load_angiogram(
        RCA, geometry_json=json_path, overrides=GeometryOverrides(sid_mm=1200.0), frame=10
    )
    assert ang.geometry.sid_mm == 1200.0 and ang.geometry.sod_mm == 800.0


def test_fallbacks_are_derived_and_noted(
    tmp_path: Path, xa_geometry: Callable[..., Any], run_with_line: Callable[..., Any]
) -> None:
    frames = run_with_line([500.0])
    g = xa_geometry()
    # SOD from the magnification factor, spacing from FieldOfViewDimensions
    path = tmp_path / "fov.dcm"
    _write_test_dicom(
        path,
        frames,
        g,
        remove=["DistanceSourceToPatient", "ImagerPixelSpacing"],
        set_values={"FieldOfViewDimensions": [24, 16]},
    )
    ang = load_angiogram(path)
    assert ang.geometry.sod_mm == pytest.approx(720.0, abs=1e-5)
    assert ang.geometry.pixel_spacing_mm == pytest.approx((24 / 80, 16 / 64))
    notes = " | ".join(ang.geometry_notes)
    assert "EstimatedRadiographicMagnificationFactor" in notes
    assert "FieldOfViewDimensions" in notes and "ImagerPixelSpacing missing" in notes
    # spacing from PixelSpacing (at the isocenter) times the magnification SID/SOD
    path = tmp_path / "ps.dcm"
    _write_test_dicom(
        path,
        frames,
        g,
        remove=["ImagerPixelSpacing"],
        set_values={"PixelSpacing": [0.2, 0.25]},
    )
    ang = load_angiogram(path)
    assert ang.geometry.pixel_spacing_mm == pytest.approx((0.2 * 976 / 720, 0.25 * 976 / 720))
    assert any("PixelSpacing" in note for note in ang.geometry_notes)


def test_missing_angle_needs_an_override(
    tmp_path: Path, xa_geometry: Callable[..., Any], run_with_line: Callable[..., Any]
) -> None:
    path = tmp_path / "noangle.dcm"
    _write_test_dicom(
        path, run_with_line([500.0]), xa_geometry(), remove=["PositionerPrimaryAngle"]
    )
    with pytest.raises(LoadError, match=r"noangle\.dcm: PositionerPrimaryAngle \(0018,1510\)"):
        load_angiogram(path)
    ang = load_angiogram(path, overrides=GeometryOverrides(alpha_deg=12.0))
    assert ang.geometry.alpha_deg == 12.0
    assert describe_file(path)["geometry"]["alpha_deg"] is None


def test_override_replaces_header_value_and_says_so() -> None:
    ang = load_angiogram(IM7, overrides=GeometryOverrides(sod_mm=700.0))
    assert ang.geometry.sod_mm == 700.0
    assert ang.geometry_notes == ("SOD 700 from override (header says 720)",)


def test_inconsistent_geometry_is_a_load_error() -> None:
    # each value in its range, but the isocenter beyond the detector (SID 976 in the header)
    overrides = GeometryOverrides(sod_mm=1000.0)
    with pytest.raises(LoadError, match=r"IM7\.dcm: invalid geometry: SOD 1000 mm \(override\) "
                       r"must be below SID 976 mm \(DistanceSourceToDetector"):
        load_angiogram(IM7, overrides=overrides)
    with pytest.raises(LoadError, match=r"^override: sod_mm = 2000 mm is outside .*400 to 1300"):
        GeometryOverrides(sod_mm=2000.0)
