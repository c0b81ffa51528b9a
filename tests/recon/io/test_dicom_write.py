"""recon.io.dicom_write: XA files written and read back."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from recon.io.angiogram import load_angiogram
from recon.io.describe import describe_file
from recon.io.dicom_write import write_xa_dicom


def test_write_read_round_trip_12_bit_multiframe(
    tmp_path: Path, xa_geometry: Callable[..., Any]
) -> None:
    rng = np.random.default_rng(7)
    frames = rng.integers(0, 4096, size=(5, 80, 64), dtype=np.uint16)
    geometry = xa_geometry()
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


def test_write_read_single_frame_8_bit(tmp_path: Path, xa_geometry: Callable[..., Any]) -> None:
    frame = np.arange(80 * 64, dtype=np.uint16).reshape(80, 64) % 256
    path = tmp_path / "single.dcm"
    write_xa_dicom(path, frame.astype(np.uint8), xa_geometry(), bits_stored=8)
    ang = load_angiogram(path)
    assert ang.n_frames == 1 and ang.frames is None and ang.frame_reason == "single frame"
    np.testing.assert_array_equal(ang.image, frame.astype(np.float32))


def test_writer_rejects_bad_input(tmp_path: Path, xa_geometry: Callable[..., Any]) -> None:
    with pytest.raises(ValueError, match="does not fit in 12 bits"):
        write_xa_dicom(tmp_path / "x.dcm", np.full((80, 64), 5000, np.uint16), xa_geometry())
    with pytest.raises(ValueError, match="geometry says"):
        write_xa_dicom(tmp_path / "x.dcm", np.zeros((30, 64), np.uint16), xa_geometry())
    with pytest.raises(ValueError, match="unsigned integer"):
        write_xa_dicom(tmp_path / "x.dcm", np.zeros((80, 64), np.float32), xa_geometry())
    with pytest.raises(ValueError, match="r_wave_frames"):
        write_xa_dicom(
            tmp_path / "x.dcm", np.zeros((3, 80, 64), np.uint16), xa_geometry(), r_wave_frames=[3]
        )
    assert not (tmp_path / "x.dcm").exists()
