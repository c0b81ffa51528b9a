"""Tests of recon.dicom_io against the real files in tests/data and synthetic files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy import ndimage

from recon.dicom_io import (
    Angiogram,
    GeometryOverrides,
    LoadError,
    _write_test_dicom,
    describe_file,
    format_description,
    load_angiogram,
    vessel_contrast_scores,
    write_xa_dicom,
)
from recon.geometry import ViewGeometry

DATA = Path(__file__).resolve().parents[1] / "data"
IM7 = DATA / "IM7.dcm"
IM8 = DATA / "IM8.dcm"
RCA = DATA / "rca-cine-ecg.dcm"
CT_SOP_CLASS = "1.2.840.10008.5.1.4.1.1.2"


def _geometry(rows: int = 40, cols: int = 32) -> ViewGeometry:
    return ViewGeometry(
        alpha_deg=-29.3,
        beta_deg=25.5,
        sid_mm=976.0,
        sod_mm=720.0,
        pixel_spacing_mm=(0.390625, 0.390625),
        rows=rows,
        cols=cols,
    )


def _run_with_line(depths: list[float], rows: int = 40, cols: int = 32) -> np.ndarray:
    """(F, rows, cols) uint16 frames: flat 2000 background, a dark vertical line per frame."""
    frames = np.full((len(depths), rows, cols), 2000, dtype=np.uint16)
    for k, depth in enumerate(depths):
        frames[k, 5:-5, cols // 2 - 1 : cols // 2 + 1] = int(2000 - depth)
    return frames


# ------------------------------------------------------------ real phantom
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


# ------------------------------------------------------------ clinical cine
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


# ------------------------------------------------------------ round trips
def test_write_read_round_trip_12_bit_multiframe(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    frames = rng.integers(0, 4096, size=(5, 40, 32), dtype=np.uint16)
    geometry = _geometry()
    path = tmp_path / "run.dcm"
    write_xa_dicom(
        path,
        frames,
        geometry,
        frame_time_ms=33.0,
        r_wave_frames=[1, 3],
        representative_frame=2,
        series_description="round trip",
    )
    ang = load_angiogram(path)
    assert ang.geometry == geometry
    assert ang.frame_index == 2 and ang.frame_reason == "RepresentativeFrameNumber 3"
    assert ang.frame_time_ms == 33.0 and ang.n_frames == 5
    np.testing.assert_array_equal(ang.frames, frames.astype(np.float32))
    assert ang.info["bits_stored"] == 12 and ang.info["photometric"] == "MONOCHROME2"
    assert ang.info["r_wave_pointer"] == [2, 4] and ang.info["r_wave_frames"] == [1, 3]
    assert ang.info["sop_class"] == "1.2.840.10008.5.1.4.1.1.12.1"
    assert describe_file(path, show_patient=True)["patient_name"] == "PHANTOM"
    assert not list(tmp_path.glob(".*tmp"))  # no temporary file left behind


def test_write_read_single_frame_8_bit(tmp_path: Path) -> None:
    frame = np.arange(40 * 32, dtype=np.uint16).reshape(40, 32) % 256
    path = tmp_path / "single.dcm"
    write_xa_dicom(path, frame.astype(np.uint8), _geometry(), bits_stored=8)
    ang = load_angiogram(path)
    assert ang.n_frames == 1 and ang.frames is None and ang.frame_reason == "single frame"
    np.testing.assert_array_equal(ang.image, frame.astype(np.float32))


def test_writer_rejects_bad_input(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="does not fit in 12 bits"):
        write_xa_dicom(tmp_path / "x.dcm", np.full((40, 32), 5000, np.uint16), _geometry())
    with pytest.raises(ValueError, match="geometry says"):
        write_xa_dicom(tmp_path / "x.dcm", np.zeros((30, 32), np.uint16), _geometry())
    with pytest.raises(ValueError, match="unsigned integer"):
        write_xa_dicom(tmp_path / "x.dcm", np.zeros((40, 32), np.float32), _geometry())
    with pytest.raises(ValueError, match="r_wave_frames"):
        write_xa_dicom(
            tmp_path / "x.dcm", np.zeros((3, 40, 32), np.uint16), _geometry(), r_wave_frames=[3]
        )
    assert not (tmp_path / "x.dcm").exists()


def test_monochrome1_is_inverted(tmp_path: Path) -> None:
    frames = _run_with_line([0.0, 500.0])
    path = tmp_path / "mono1.dcm"
    _write_test_dicom(
        path, frames, _geometry(), set_values={"PhotometricInterpretation": "MONOCHROME1"}
    )
    ang = load_angiogram(path, frame=1)
    np.testing.assert_array_equal(ang.image, 4095.0 - frames[1])
    assert ang.info["inverted_on_load"]


# ------------------------------------------------------------ frame choice
def test_strongest_contrast_frame_is_chosen_without_pointers(tmp_path: Path) -> None:
    depths = [0.0, 200.0, 400.0, 900.0, 300.0]
    scores = vessel_contrast_scores(_run_with_line(depths))
    assert np.argmax(scores) == 3
    assert np.all(np.diff(scores[:4]) > 0)
    path = tmp_path / "run.dcm"
    write_xa_dicom(path, _run_with_line(depths), _geometry())
    ang = load_angiogram(path)
    assert ang.frame_index == 3 and ang.frame_reason == "strongest vessel contrast"


def test_r_wave_frame_with_best_contrast_is_chosen(tmp_path: Path) -> None:
    depths = [0.0, 300.0, 900.0, 100.0, 600.0, 0.0]
    path = tmp_path / "ecg.dcm"
    write_xa_dicom(path, _run_with_line(depths), _geometry(), r_wave_frames=[0, 3, 4])
    ang = load_angiogram(path)
    # frame 2 has the most contrast overall, but it is not at an R wave
    assert ang.frame_index == 4
    assert ang.frame_reason.startswith("end-diastolic: R wave at frame 4")


# ------------------------------------------------------------ fallbacks
def test_fallbacks_are_derived_and_noted(tmp_path: Path) -> None:
    frames = _run_with_line([500.0])
    g = _geometry()
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
    assert ang.geometry.pixel_spacing_mm == pytest.approx((24 / 40, 16 / 32))
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


def test_missing_angle_needs_an_override(tmp_path: Path) -> None:
    path = tmp_path / "noangle.dcm"
    _write_test_dicom(path, _run_with_line([500.0]), _geometry(), remove=["PositionerPrimaryAngle"])
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
    with pytest.raises(LoadError, match=r"IM7\.dcm: invalid geometry: sod_mm"):
        load_angiogram(IM7, overrides=GeometryOverrides(sod_mm=2000.0))


# ------------------------------------------------------------ bad files
def test_bad_files_raise_one_line_load_errors(tmp_path: Path) -> None:
    noise = tmp_path / "noise.dcm"
    noise.write_bytes(np.random.default_rng(0).bytes(4096))
    empty = tmp_path / "empty.dcm"
    empty.write_bytes(b"")
    data = IM7.read_bytes()
    header_cut = tmp_path / "cut-header.dcm"
    header_cut.write_bytes(data[:700])
    pixel_cut = tmp_path / "cut-pixels.dcm"
    pixel_cut.write_bytes(data[: len(data) // 2])
    frame = _run_with_line([100.0])[0].astype(np.uint8)
    ct = tmp_path / "ct.dcm"
    _write_test_dicom(
        ct,
        frame,
        _geometry(),
        set_values={"SOPClassUID": CT_SOP_CLASS, "Modality": "CT"},
    )
    mpeg = tmp_path / "mpeg.dcm"
    _write_test_dicom(mpeg, frame, _geometry(), garbage_compressed_as="1.2.840.10008.1.2.4.100")
    bad_jpeg = tmp_path / "bad-jpeg.dcm"
    _write_test_dicom(bad_jpeg, frame, _geometry(), garbage_compressed_as="1.2.840.10008.1.2.4.50")
    cases = {
        noise: "not a DICOM file",
        empty: "not a DICOM file",
        header_cut: "truncated",
        pixel_cut: "truncated",
        ct: "CT Image Storage",
        mpeg: "cannot decode the pixel data (MPEG2",
        bad_jpeg: "cannot decode the pixel data (JPEG Baseline",
        tmp_path / "absent.dcm": "no such file",
    }
    for path, expected in cases.items():
        for fn in (load_angiogram, describe_file):
            with pytest.raises(LoadError) as err:
                fn(path)
            message = str(err.value)
            assert message.startswith(f"{path}: "), message
            assert "\n" not in message
            assert expected in message


# ------------------------------------------------------------ PNG + JSON
def _geometry_json(path: Path, **extra: object) -> None:
    data = {
        "alpha_deg": 30.7,
        "beta_deg": 23.6,
        "sid_mm": 976,
        "sod_mm": 720,
        "pixel_spacing_mm": [0.5, 0.4],
    }
    data.update(extra)
    path.write_text(json.dumps(data))


def test_png_with_sidecar_json(tmp_path: Path) -> None:
    pixels = (np.arange(30 * 20).reshape(30, 20) * 50).astype(np.uint16)
    png = tmp_path / "view.png"
    Image.fromarray(pixels).save(png)
    _geometry_json(tmp_path / "view.json", rows=30, cols=20)
    ang = load_angiogram(png)
    assert isinstance(ang, Angiogram)
    np.testing.assert_array_equal(ang.image, pixels.astype(np.float32))
    expected = ViewGeometry(30.7, 23.6, 976.0, 720.0, (0.5, 0.4), rows=30, cols=20)
    assert ang.geometry == expected
    assert ang.n_frames == 1 and ang.frame_reason == "single frame" and ang.frames is None


def test_rgb_tiff_with_named_json_is_grey(tmp_path: Path) -> None:
    grey = np.tile(np.arange(0, 250, 10, dtype=np.uint8), (12, 1))  # (12, 25)
    rgb = np.stack([grey, grey, grey], axis=-1)
    tif = tmp_path / "view.tif"
    Image.fromarray(rgb).save(tif)
    js = tmp_path / "geometry-a.json"
    _geometry_json(js)
    ang = load_angiogram(tif, geometry_json=js)
    np.testing.assert_allclose(ang.image, grey.astype(np.float32), atol=1e-3)
    assert ang.geometry.rows == 12 and ang.geometry.cols == 25


def test_png_geometry_problems(tmp_path: Path) -> None:
    png = tmp_path / "bare.png"
    Image.fromarray(np.zeros((10, 10), np.uint8)).save(png)
    with pytest.raises(LoadError, match=r"bare\.png: alpha_deg is missing"):
        load_angiogram(png)
    _geometry_json(tmp_path / "bare.json", rows=11)
    with pytest.raises(LoadError, match=r"bare\.json: rows is 11"):
        load_angiogram(png)
    _geometry_json(tmp_path / "bare.json", sid=900)
    with pytest.raises(LoadError, match=r"bare\.json: unknown key 'sid'"):
        load_angiogram(png)
    (tmp_path / "bare.json").write_text("{not json")
    with pytest.raises(LoadError, match=r"bare\.json: not valid JSON"):
        load_angiogram(png)


def test_overrides_from_json(tmp_path: Path) -> None:
    js = tmp_path / "ov.json"
    js.write_text(json.dumps({"sid_mm": 1000, "pixel_spacing_mm": [0.2, 0.3]}))
    ov = GeometryOverrides.from_json(js)
    assert ov.sid_mm == 1000.0 and ov.pixel_spacing_mm == (0.2, 0.3)
    assert ov.alpha_deg is None and ov.sod_mm is None
    js.write_text(json.dumps({"sid_mm": -5}))
    with pytest.raises(LoadError, match="sid_mm must be positive"):
        GeometryOverrides.from_json(js)
    with pytest.raises(LoadError, match="pixel_spacing_mm"):
        GeometryOverrides(pixel_spacing_mm=(0.2, 0.0))  # type: ignore[arg-type]
