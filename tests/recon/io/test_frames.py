"""recon.io.frames: the frame chosen from a run, and the vessel-contrast score."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from recon.io.angiogram import load_angiogram
from recon.io.dicom_write import write_xa_dicom
from recon.io.frames import vessel_contrast_scores


def test_strongest_contrast_frame_is_chosen_without_pointers(
    tmp_path: Path, xa_geometry: Callable[..., Any], run_with_line: Callable[..., Any]
) -> None:
    depths = [0.0, 200.0, 400.0, 900.0, 300.0]
    scores = vessel_contrast_scores(run_with_line(depths))
    assert np.argmax(scores) == 3
    assert np.all(np.diff(scores[:4]) > 0)
    path = tmp_path / "run.dcm"
    write_xa_dicom(path, run_with_line(depths), xa_geometry())
    ang = load_angiogram(path)
    assert ang.frame_index == 3 and ang.frame_reason == "strongest vessel contrast"


def test_r_wave_frame_with_best_contrast_is_chosen(
    tmp_path: Path, xa_geometry: Callable[..., Any], run_with_line: Callable[..., Any]
) -> None:
    depths = [0.0, 300.0, 900.0, 100.0, 600.0, 0.0]
    path = tmp_path / "ecg.dcm"
    write_xa_dicom(path, run_with_line(depths), xa_geometry(), r_wave_frames=[0, 3, 4])
    ang = load_angiogram(path)
    # frame 2 has the most contrast overall, but it is not at an R wave
    assert ang.frame_index == 4
    assert ang.frame_reason.startswith("end-diastolic: R wave at frame 4")
