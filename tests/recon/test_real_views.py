"""The eight real views of the static phantom (tests/data/IM1..IM8, see ORIGIN.md).

One branch (the "diagonal branch": from its junction with the long arc to
the end of its contrast column) is clicked in three pairs, IM1+IM2, IM3+IM4
and IM7+IM8 (tests/data/im*_im*_seeds.json), and reconstructed from each.

- Its median lumen diameter must agree between the pairs within 5 %.
- Its 3D centerline, projected into each of the six views that pair did not
  use, must lie on that view's vessel ridge: median distance at most 1 px.

The headers disagree with each other: IM5-IM8 are offset 9-25 mm from
IM1-IM4 (a rig offset the headers do not record), while IM1-IM4 agree to a
few px. So the held-out comparison allows **one 2D shift per held-out view**:
the shift of the projected curve that maximises a dark-ridge response
summed along it, searched over +-100 px (IM6 needs ~80 px from IM1-IM4's
frame) and refined to 0.1 px. The distance to the ridge is then measured
independently of that response: the darkest point of the lightly smoothed
image across the projected curve, within +-5 px (5 px when it is not found
inside). The first and last 2 mm of the curve are left out (where the
vessel starts at its parent and ends). The ridge response here is the
test's own (Hessian, three scales), so the check does not move with the
tracing's vesselness.

The measured figures are written to test-artifacts/real_views.json.

Also here: the header facts and warnings for inputs whose radii are less
certain (8-bit, lossy, display-processed), on IM7 and the JPEG Baseline
clinical run rca-cine-ecg.dcm.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage as ndi
from scipy.signal import fftconvolve

from recon.io import GeometryOverrides, load_angiogram, load_seeds
from recon.pipeline import (
    TRACER_CHOICES,
    ReconstructionOptions,
    input_warnings,
    reconstruct_pair,
)

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
PAIRS = ((1, 2), (3, 4), (7, 8))
DIAMETER_SPREAD_MAX = 0.05  # max / min of the pairs' median diameters, minus 1
HELD_OUT_MEDIAN_MAX_PX = 1.0
SHIFT_REACH_PX = 100
TRIM_MM = 2.0


# ------------------------------------------------------------------ helpers
def ridge_response(image: np.ndarray, sigmas=(1.5, 2.5, 3.5)) -> np.ndarray:
    """Dark-ridge response (H, W): the largest Hessian eigenvalue (positive across a
    dark tube), scale-normalised, max over scales, 1 at the 99.9th percentile."""
    img = np.asarray(image, dtype=float)
    out = np.zeros_like(img)
    for s in sigmas:
        rr = ndi.gaussian_filter(img, s, order=(2, 0))
        cc = ndi.gaussian_filter(img, s, order=(0, 2))
        rc = ndi.gaussian_filter(img, s, order=(1, 1))
        lam = 0.5 * (rr + cc) + np.sqrt(0.25 * (rr - cc) ** 2 + rc**2)
        out = np.maximum(out, s**2 * np.maximum(lam, 0.0))
    return out / max(float(np.percentile(out, 99.9)), 1e-12)


def _sample(image: np.ndarray, points_px: np.ndarray) -> np.ndarray:
    return ndi.map_coordinates(image, [points_px[..., 1], points_px[..., 0]], order=1,
                               mode="constant")


def best_shift(response: np.ndarray, points_px: np.ndarray, reach_px: int = SHIFT_REACH_PX
               ) -> np.ndarray:
    """The 2D shift (2,) (col, row) of the points (N, 2) that maximises the response
    summed along them: every integer shift within +-reach (one FFT correlation), then
    a 0.1 px grid within +-1 px of the best."""
    q = np.round(points_px).astype(int)
    lo = q.min(axis=0)
    kernel = np.zeros(tuple((q.max(axis=0) - lo + 1)[::-1]))
    np.add.at(kernel, (q[:, 1] - lo[1], q[:, 0] - lo[0]), 1.0)
    padded = np.pad(response, reach_px)
    corr = fftconvolve(padded, kernel[::-1, ::-1], mode="valid")
    d = np.arange(-reach_px, reach_px + 1)
    rows, cols = d + lo[1] + reach_px, d + lo[0] + reach_px
    ok_r = (rows >= 0) & (rows < corr.shape[0])
    ok_c = (cols >= 0) & (cols < corr.shape[1])
    score = np.full((len(d), len(d)), -np.inf)
    score[np.ix_(ok_r, ok_c)] = corr[np.ix_(rows[ok_r], cols[ok_c])]
    iy, ix = np.unravel_index(np.argmax(score), score.shape)
    coarse = np.array([d[ix], d[iy]], dtype=float)
    f = np.arange(-1.0, 1.001, 0.1)
    fine = np.array([[_sample(response, points_px + coarse + [fx, fy]).mean() for fx in f]
                     for fy in f])
    jy, jx = np.unravel_index(np.argmax(fine), fine.shape)
    return coarse + [f[jx], f[jy]]


def ridge_distance(smooth: np.ndarray, points_px: np.ndarray, half_px: float = 5.0,
                   step_px: float = 0.25) -> np.ndarray:
    """Distance (N,) of each point of a curve (N, 2) to the darkest point of ``smooth``
    across the curve within +-half_px (subpixel); half_px where none is inside."""
    t = np.gradient(points_px, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    n = np.column_stack([-t[:, 1], t[:, 0]])
    o = np.arange(-half_px, half_px + step_px / 2, step_px)
    prof = _sample(smooth, points_px[:, None, :] + o[None, :, None] * n[:, None, :])
    k = np.argmin(prof, axis=1)
    inside = (k > 0) & (k < len(o) - 1)
    kk = np.clip(k, 1, len(o) - 2)
    r = np.arange(len(points_px))
    f0, f1, f2 = prof[r, kk - 1], prof[r, kk], prof[r, kk + 1]
    den = f0 - 2 * f1 + f2
    safe = np.where(np.abs(den) > 1e-9, den, 1.0)
    vertex = np.where(np.abs(den) > 1e-9, np.clip(0.5 * (f0 - f2) / safe, -0.5, 0.5), 0.0)
    return np.where(inside, np.abs(o[kk] + vertex * step_px), half_px)


# ------------------------------------------------------------------ fixtures
@pytest.fixture(scope="module")
def views() -> dict:
    return {k: load_angiogram(DATA / f"IM{k}.dcm") for k in range(1, 9)}


@pytest.fixture(scope="module", params=TRACER_CHOICES)
def reconstructions(views, request) -> dict:
    """The three pairs, with each tracer (the 3D tracer must keep what the 2D one does)."""
    options = ReconstructionOptions(tracer=request.param)
    return {
        (i, j): reconstruct_pair(views[i], views[j], load_seeds(DATA / f"im{i}_im{j}_seeds.json"),
                                 options)
        for i, j in PAIRS
    }


@pytest.fixture(scope="module")
def images(views) -> tuple[dict, dict]:
    """Per view: the ridge response (for the shift) and the smoothed image (for the distance)."""
    return ({k: ridge_response(a.image) for k, a in views.items()},
            {k: ndi.gaussian_filter(a.image.astype(float), 1.5) for k, a in views.items()})


def held_out_rows(views: dict, reconstructions: dict, images: tuple[dict, dict]) -> list[dict]:
    """Per pair and held-out view: the shift used, the median ridge distance with and
    without it."""
    ridge, smooth = images
    rows = []
    for (i, j), rec in reconstructions.items():
        c3 = rec.centerline_3d
        keep = (c3.s_mm > TRIM_MM) & (c3.s_mm < c3.length_mm - TRIM_MM)
        for k in sorted(set(views) - {i, j}):
            p = views[k].geometry.project(c3.X_world[keep])
            shift = best_shift(ridge[k], p)
            rows.append({
                "pair": f"IM{i}+IM{j}", "view": f"IM{k}",
                "shift_px": [round(float(x), 1) for x in shift],
                "median_px_unshifted": round(float(np.median(ridge_distance(smooth[k], p))), 2),
                "median_px": round(float(np.median(ridge_distance(smooth[k], p + shift))), 2),
            })
    return rows


@pytest.fixture(scope="module")
def held_out(views, reconstructions, images) -> list[dict]:
    """:func:`held_out_rows` of the pairs' reconstructions. Written to
    test-artifacts/real_views.json with the diameters."""
    rows = held_out_rows(views, reconstructions, images)
    out = ROOT / "test-artifacts"
    out.mkdir(exist_ok=True)
    summary = {
        "median_diameter_mm": {
            f"IM{i}+IM{j}": round(float(np.median(rec.profile.diameter_mm)), 3)
            for (i, j), rec in reconstructions.items()
        },
        "median_diameter_per_view_mm": {
            f"IM{i}+IM{j}": [round(float(np.median(2 * rec.centerline_3d.radius_a_mm)), 3),
                             round(float(np.median(2 * rec.centerline_3d.radius_b_mm)), 3)]
            for (i, j), rec in reconstructions.items()
        },
        "length_mm": {f"IM{i}+IM{j}": round(rec.centerline_3d.length_mm, 1)
                      for (i, j), rec in reconstructions.items()},
        "held_out": rows,
    }
    (out / "real_views.json").write_text(json.dumps(summary, indent=1))
    return rows


# ------------------------------------------------------------------ tests
def test_the_pairs_trace_the_same_branch(reconstructions) -> None:
    lengths = {p: rec.centerline_3d.length_mm for p, rec in reconstructions.items()}
    assert max(lengths.values()) / min(lengths.values()) < 1.1, lengths
    for rec in reconstructions.values():
        assert rec.consistency is None or rec.consistency.ok, rec.consistency.stretches


def test_the_median_diameters_of_the_pairs_agree_within_5_pct(reconstructions) -> None:
    medians = {f"IM{i}+IM{j}": float(np.median(rec.profile.diameter_mm))
               for (i, j), rec in reconstructions.items()}
    spread = max(medians.values()) / min(medians.values()) - 1.0
    shown = ", ".join(f"{k} {v:.3f} mm" for k, v in medians.items())
    assert spread <= DIAMETER_SPREAD_MAX, (
        f"median diameters {shown}: spread {100 * spread:.1f} % (target at most "
        f"{100 * DIAMETER_SPREAD_MAX:.0f} %)")


def test_held_out_views_see_the_branch_on_their_ridge(held_out) -> None:
    assert len(held_out) == 6 * len(PAIRS)
    table = "; ".join(
        f"{r['pair']}->{r['view']} {r['median_px']:.2f} px (shift {r['shift_px'][0]:+.1f},"
        f"{r['shift_px'][1]:+.1f}; unshifted {r['median_px_unshifted']:.2f})" for r in held_out)
    failing = [r for r in held_out if r["median_px"] > HELD_OUT_MEDIAN_MAX_PX]
    assert not failing, f"median distance to the ridge over {HELD_OUT_MEDIAN_MAX_PX} px: {table}"
    # IM1-IM4 agree with each other to a few px: their mutual shifts are small.
    for r in held_out:
        if r["pair"] in ("IM1+IM2", "IM3+IM4") and r["view"] in ("IM1", "IM2", "IM3", "IM4"):
            assert np.hypot(*r["shift_px"]) < 12.0, r


# ------------------------------------------- calibration never makes the header worse
CALIBRATION_WORSE_MAX_PX = 0.2


def test_calibration_is_no_worse_than_the_header_in_every_held_out_view(
    views, images
) -> None:
    """Issue 14: every pair with a seeds file (IM1+IM2, IM3+IM4, IM7+IM8; all at least
    50 degrees apart) reconstructed with the calibration the clicks support
    (``calibration="supported"``, not yet the default) projects
    into each of its six held-out views (after that view's best 2D shift) no more than
    0.2 px (median) further from the vessel than the reconstruction at the header pose.
    (The full six-parameter correction, the default, fails this: IM3+IM4 -> IM8 0.75
    against the header's 0.39 px, IM1+IM2 -> IM5 0.46 against 0.19.)"""
    def reconstruct(calibration: str) -> dict:
        return {(i, j): reconstruct_pair(views[i], views[j],
                                         load_seeds(DATA / f"im{i}_im{j}_seeds.json"),
                                         ReconstructionOptions(calibration=calibration))
                for i, j in PAIRS}

    reconstructions = reconstruct("supported")
    held_out = held_out_rows(views, reconstructions, images)
    at_header = {(r["pair"], r["view"]): r["median_px"]
                 for r in held_out_rows(views, reconstruct("header"), images)}
    worse = [f"{r['pair']}->{r['view']} {r['median_px']:.2f} px against the header's "
             f"{at_header[r['pair'], r['view']]:.2f}" for r in held_out
             if r["median_px"] > at_header[r["pair"], r["view"]] + CALIBRATION_WORSE_MAX_PX]
    assert not worse, "; ".join(worse)
    for (i, j), rec in reconstructions.items():
        report = rec.report()["calibration"]
        assert report["correction"] in ("header", "translation", "full")
        assert report["observability"]["directions"]["translation_baseline"]["status"] in (
            "header", "partly"), (i, j)


# ----------------------------------------------------- inputs with less certain radii
def test_header_facts_and_warning_of_a_display_processed_8_bit_view(views) -> None:
    info = views[7].info
    assert info["pixel_intensity_relationship"] == "DRM"
    assert info["lossy"] is False  # JPEG Lossless
    assert info["bits_stored"] == 8
    assert views[1].info["pixel_intensity_relationship"] == "DISP"
    assert input_warnings(info, "B") == [
        "view B: 8-bit, display-processed image (PixelIntensityRelationship DRM); "
        "its radii are less certain"]


def test_header_facts_and_warning_of_a_lossy_jpeg_baseline_run() -> None:
    ov = GeometryOverrides(sid_mm=1000.0, sod_mm=750.0, pixel_spacing_mm=(0.3, 0.3))
    info = load_angiogram(DATA / "rca-cine-ecg.dcm", overrides=ov).info
    assert info["transfer_syntax"] == "1.2.840.10008.1.2.4.50"
    assert info["lossy"] is True
    assert info["pixel_intensity_relationship"] == "LIN"  # linear: not display-processed
    assert info["bits_stored"] == 8
    assert input_warnings(info, "A") == [
        "view A: 8-bit, lossy image (JPEG Baseline (Process 1)); its radii are less certain"]


def test_no_warning_for_a_12_bit_lossless_linear_image() -> None:
    info = {"bits_stored": 12, "lossy": False, "pixel_intensity_relationship": "LOG"}
    assert input_warnings(info, "A") == []
    assert input_warnings({}, "A") == []  # not recorded (the phantom): nothing to say
    assert input_warnings({"bits_stored": 16, "pixel_intensity_relationship": "DISP"}, "A") == [
        "view A: display-processed image (PixelIntensityRelationship DISP); "
        "its radii are less certain"]


def test_the_report_carries_the_warnings_and_the_consistency(reconstructions) -> None:
    report = json.loads(json.dumps(reconstructions[(7, 8)].report()))
    assert report["warnings"][:2] == [
        "view A: 8-bit, display-processed image (PixelIntensityRelationship DRM); "
        "its radii are less certain",
        "view B: 8-bit, display-processed image (PixelIntensityRelationship DRM); "
        "its radii are less certain"]
    consistency = report["consistency"]
    assert consistency["ok"] is True and consistency["stretches"] == []
    assert set(consistency["max_offset_px"]) == {"a", "b"}
    assert max(consistency["max_offset_px"].values()) < 3.0
    ratios = [iv["ratio"] for v in ("a", "b") for iv in consistency["arc_length_ratio"][v]]
    assert ratios and all(abs(r - 1.0) < 0.05 for r in ratios)


def test_no_catheter_is_found_in_the_static_phantom_which_has_none(reconstructions) -> None:
    """The static phantom's tubes do not enter the field as a guiding catheter would: no
    view of any pair reports one (no false catheter on real images)."""
    for rec in reconstructions.values():
        assert rec.report()["guiding_catheter"] == {"a": [], "b": []}
