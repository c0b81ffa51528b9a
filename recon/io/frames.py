"""Which frame of a run to reconstruct from, and a cheap vessel-contrast score.

Frame indices in the Python API of :mod:`recon.io` are 0-based everywhere (the
``frame`` argument, ``Angiogram.frame_index``, ``representative_frame`` and
``r_wave_frames`` of :func:`recon.io.dicom_write.write_xa_dicom`,
``info["r_wave_frames"]``). DICOM frame numbers are 1-based: the Frame
Pointers module says of RepresentativeFrameNumber (0028,6010) "frame numbers
begin at 1", and the XA Image module's R Wave Pointer (0028,6040) marks the R
waves "by referencing frame numbers", numbered the same way. Both are
converted at this edge (index = number - 1); the raw values stay in
``info["representative_frame_number"]`` and ``info["r_wave_pointer"]``.
(Cross-check on tests/data/rca-cine-ecg.dcm: the R peaks of its group-5000
ECG curve, 40 samples per frame, fall at 0-based frames 20.8, 52.4 and 77.1
against R Wave Pointer 20, 53, 77: consistent with either base to within one
frame, so the standard's 1-based reading decides.)

Frame choice, first rule that applies:

1. the ``frame`` argument (0-based, validated);
2. RepresentativeFrameNumber, when in range;
3. end-diastole: the R-wave frames are end-diastolic (the R wave closes
   diastole, the coronaries are longest and slowest there); among them the one
   with the strongest vessel contrast (:func:`vessel_contrast_scores`), because
   an injection run opacifies the arteries for a few beats only and an
   end-diastolic frame without contrast is useless; ties go to the frame
   nearest the middle of the run;
4. the frame of strongest vessel contrast.
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from recon.io.raw import RawFile
from recon.types import _check_frame_index

__all__ = ["vessel_contrast_scores", "choose_frame"]


def vessel_contrast_scores(frames: ArrayLike) -> NDArray[np.float64]:
    """Cheap vessel-contrast score (F,) of each frame of a run (F, H, W).

    Each frame is block-averaged to about 128 px, its black top-hat (grey
    closing with a 9 px square minus the frame) keeps dark structures thinner
    than about 9 / 128 of the field, and the score is the 99th percentile of
    the top-hat inside the exposed field (the dark collimator border is
    masked out), divided by the frame's median brightness there so that
    exposure changes do not count as contrast. Higher = darker, better filled
    vessels.
    """
    stack = np.asarray(frames, dtype=np.float32)
    if stack.ndim == 2:
        stack = stack[None]
    if stack.ndim != 3:
        raise ValueError(f"frames must have shape (F, H, W), got {stack.shape}")
    n, h, w = stack.shape
    s = max(1, min(h, w) // 128)
    hs, ws = h // s, w // s
    small = stack[:, : hs * s, : ws * s].reshape(n, hs, s, ws, s).mean(axis=(2, 4))
    k = 9
    closed = ndimage.grey_closing(small, size=(1, k, k))
    tophat = closed - small
    bright = np.percentile(small.reshape(n, -1), 99, axis=1)[:, None, None]
    exposed = small > 0.1 * bright
    exposed = ndimage.binary_erosion(exposed, structure=np.ones((1, k, k), bool))
    masked = np.where(exposed, tophat, np.nan)
    level = np.where(exposed, small, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-masked frames give NaN
        score = np.nanpercentile(masked.reshape(n, -1), 99, axis=1)
        median = np.nanmedian(level.reshape(n, -1), axis=1)
    out = score / np.maximum(median, 1e-6)
    return np.nan_to_num(out, nan=0.0).astype(np.float64)


def choose_frame(raw: RawFile, frame: int | None, path: str) -> tuple[int, str]:
    """0-based index of the frame to use and why, by the rules of the module docstring."""
    n = raw.frames.shape[0]
    if frame is not None:
        return _check_frame_index(frame, n, path), "explicit"
    if n == 1:
        return 0, "single frame"
    ignored = []
    rep = raw.info.get("representative_frame_number")
    if rep is not None:
        if 1 <= rep <= n:
            return rep - 1, f"RepresentativeFrameNumber {rep}"
        ignored.append(f"RepresentativeFrameNumber {rep} out of range ignored")
    r_frames = raw.info.get("r_wave_frames") or []
    if r_frames:
        candidates = np.asarray(sorted(set(r_frames)))
        scores = vessel_contrast_scores(raw.frames[candidates])
        middle = (n - 1) / 2.0
        # best contrast; ties (within 1 %) broken by distance to the middle of the run
        best = scores.max()
        tied = candidates[scores >= best * 0.99 - 1e-12]
        index = int(tied[np.argmin(np.abs(tied - middle))])
        pointer = ", ".join(str(k) for k in raw.info.get("r_wave_pointer", []))
        reason = (
            f"end-diastolic: R wave at frame {index} (0-based; R Wave Pointer {pointer}, "
            f"1-based), the R-wave frame with the strongest vessel contrast"
        )
        return index, reason
    scores = vessel_contrast_scores(raw.frames)
    index = int(np.argmax(scores))
    reason = "strongest vessel contrast"
    if ignored:
        reason += f" ({'; '.join(ignored)})"
    return index, reason
