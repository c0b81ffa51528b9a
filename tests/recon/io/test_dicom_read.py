"""recon.io.dicom_read: MONOCHROME1, and files that cannot be read (one-line LoadErrors)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from recon.errors import LoadError
from recon.io.angiogram import load_angiogram
from recon.io.describe import describe_file
from recon.io.dicom_write import _write_test_dicom

DATA = Path(__file__).resolve().parents[2] / "data"
IM7 = DATA / "IM7.dcm"
CT_SOP_CLASS = "1.2.840.10008.5.1.4.1.1.2"


def test_monochrome1_is_inverted(
    tmp_path: Path, xa_geometry: Callable[..., Any], run_with_line: Callable[..., Any]
) -> None:
    frames = run_with_line([0.0, 500.0])
    path = tmp_path / "mono1.dcm"
    _write_test_dicom(
        path, frames, xa_geometry(), set_values={"PhotometricInterpretation": "MONOCHROME1"}
    )
    ang = load_angiogram(path, frame=1)
    np.testing.assert_array_equal(ang.image, 4095.0 - frames[1])
    assert ang.info["inverted_on_load"]


def test_bad_files_raise_one_line_load_errors(
    tmp_path: Path, xa_geometry: Callable[..., Any], run_with_line: Callable[..., Any]
) -> None:
    noise = tmp_path / "noise.dcm"
    noise.write_bytes(np.random.default_rng(0).bytes(4096))
    empty = tmp_path / "empty.dcm"
    empty.write_bytes(b"")
    data = IM7.read_bytes()
    header_cut = tmp_path / "cut-header.dcm"
    header_cut.write_bytes(data[:700])
    pixel_cut = tmp_path / "cut-pixels.dcm"
    pixel_cut.write_bytes(data[: len(data) // 2])
    frame = run_with_line([100.0])[0].astype(np.uint8)
    ct = tmp_path / "ct.dcm"
    _write_test_dicom(
        ct,
        frame,
        xa_geometry(),
        set_values={"SOPClassUID": CT_SOP_CLASS, "Modality": "CT"},
    )
    mpeg = tmp_path / "mpeg.dcm"
    _write_test_dicom(mpeg, frame, xa_geometry(), garbage_compressed_as="1.2.840.10008.1.2.4.100")
    bad_jpeg = tmp_path / "bad-jpeg.dcm"
    _write_test_dicom(
        bad_jpeg, frame, xa_geometry(), garbage_compressed_as="1.2.840.10008.1.2.4.50"
    )
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
