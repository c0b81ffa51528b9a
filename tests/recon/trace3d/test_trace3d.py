"""recon.trace3d: the 3D path both views vote on, its evidence, its corridor, and the
pipeline's --tracer 3d, on small cases with known answers and on a phantom pair."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import ndimage as ndi
from support import DEMO, assert_one_line_error, run_cli

from recon.bench.centerline import truth_gap_px
from recon.bench.common import case_angiograms
from recon.pipeline import ReconstructionOptions, reconstruct_pair
from recon.synth import make_phantom
from recon.trace import TraceError, compute_vesselness
from recon.trace3d import (
    ambiguous_stretches,
    clicks_on_path,
    trace_path_3d,
    view_evidence,
)
from recon.trace3d.corridor import corridor_map


def _tube_image(shape: tuple[int, int], row: float, radius_px: float, depth: float,
                background: float, noise: float, seed: int = 0) -> np.ndarray:
    """An 8-bit-like image (H, W): a horizontal dark tube ``depth`` grey levels below a
    ``background``, with Gaussian noise."""
    h, w = shape
    rr = np.arange(h, dtype=float)[:, None]
    chord = 2.0 * np.sqrt(np.clip(radius_px**2 - (rr - row) ** 2, 0.0, None))
    img = background - depth * chord / (2.0 * radius_px) * np.ones((1, w))
    img = ndi.gaussian_filter(img, 0.7)
    rng = np.random.default_rng(seed)
    return np.clip(np.rint(img + rng.normal(0.0, noise, img.shape)), 0, 255).astype(np.float32)


def test_the_evidence_answers_on_a_vessel_8_grey_levels_below_its_background() -> None:
    img = _tube_image((160, 200), 80.0, 3.0, 8.0, 120.0, 2.0)
    ev = view_evidence(img, compute_vesselness(img, pixel_mm=0.3))
    on = float(np.median(ev.support[80, 30:170]))
    off = float(np.median(ev.support[20:50, 30:170]))
    assert on > 0.5, on
    assert off < 0.15 * on, (on, off)


def test_the_corridor_keeps_the_path_and_zeroes_the_rest() -> None:
    img = _tube_image((120, 160), 40.0, 3.0, 60.0, 150.0, 1.0)
    img = np.minimum(img, _tube_image((120, 160), 80.0, 3.0, 60.0, 150.0, 1.0, seed=1))
    vmap = compute_vesselness(img, pixel_mm=0.3)
    path = np.column_stack([np.linspace(20, 140, 50), np.full(50, 40.0)])
    cut = corridor_map(vmap, path)
    ridge_before = vmap.ridge if vmap.ridge is not None else vmap.response
    ridge_after = cut.ridge if cut.ridge is not None else cut.response
    assert np.all(ridge_after[80, :] == 0.0)  # the other vessel is outside the corridor
    np.testing.assert_array_equal(ridge_after[40, 30:130], ridge_before[40, 30:130])


def test_waypoints_move_onto_the_path_and_the_ends_stay() -> None:
    path = np.column_stack([np.linspace(0, 100, 101), np.zeros(101)])
    clicks = np.array([[1.0, 3.0], [52.0, -2.0], [99.0, 1.0]])
    on = clicks_on_path(clicks, path)  # the ends stay as clicked
    np.testing.assert_allclose(on, [[1.0, 3.0], [52.0, 0.0], [99.0, 1.0]])
    # two waypoints the path passes at one place stay as clicked
    twins = np.array([[1.0, 3.0], [52.0, -9.0], [52.0, 9.0], [99.0, 1.0]])
    np.testing.assert_allclose(clicks_on_path(twins, path), twins)


@pytest.fixture(scope="module")
def phantom():
    case = make_phantom("data1", 3, stenosis_pct=50.0)
    a, b = case_angiograms(case)
    vmaps = (compute_vesselness(a.image, pixel_mm=a.geometry.pixel_mm_at_isocenter),
             compute_vesselness(b.image, pixel_mm=b.geometry.pixel_mm_at_isocenter))
    return case, a, b, vmaps


def test_the_path_lies_on_the_vessel_in_both_views(phantom) -> None:
    case, a, b, vmaps = phantom
    seg = case.seeds.segments[0]
    evs = [view_evidence(img.image, v, 2.0 / img.geometry.pixel_mm_at_isocenter)
           for img, v in zip((a, b), vmaps, strict=True)]
    path = trace_path_3d(evs[0], evs[1], case.view_a, case.view_b_true, seg.a, seg.b)
    for view in (case.view_a, case.view_b_true):
        gap, _ = truth_gap_px(path.projected(view), view, case.truth)
        assert np.median(gap) < 1.0 and gap.max() < 4.0, (np.median(gap), gap.max())
    assert abs(path.s_mm[-1] - case.truth.segment_s_mm[-1]) < 0.1 * case.truth.segment_s_mm[-1]
    assert all(st["end_mm"] >= st["start_mm"] for st in ambiguous_stretches(path))


def test_end_clicks_on_different_vessels_are_refused(phantom) -> None:
    case, a, b, vmaps = phantom
    seg = case.seeds.segments[0]
    evs = [view_evidence(img.image, v) for img, v in zip((a, b), vmaps, strict=True)]
    moved = seg.b.copy()
    moved[-1] += [0.0, 60.0]  # B's distal click far off its partner's epipolar line
    with pytest.raises(TraceError, match="do not meet in 3D") as err:
        trace_path_3d(evs[0], evs[1], case.view_a, case.view_b_true, seg.a, moved)
    assert err.value.view == "B"


def test_reconstruct_with_the_3d_tracer(phantom) -> None:
    case, a, b, vmaps = phantom
    rec = reconstruct_pair(a, b, case.seeds, ReconstructionOptions(tracer="3d"), vesselness=vmaps)
    assert rec.path_3d is not None
    for cl, view in ((rec.centerline_a, case.view_a), (rec.centerline_b, case.view_b_true)):
        gap, _ = truth_gap_px(cl.points_px, view, case.truth)
        # (this case's B trace ends 2.8 px off the truth's end with either tracer)
        assert np.median(gap) < 0.5 and gap.max() < 3.5, (np.median(gap), gap.max())
    assert abs(rec.measurements.mld_mm - case.truth.mld_mm) < 0.1
    report = rec.report()
    assert report["tracer"]["kind"] == "3d"
    assert report["tracer"]["path_length_mm"] > 0.0


def test_the_cli_runs_the_3d_tracer_and_refuses_an_unknown_one(tmp_path) -> None:
    proc = run_cli("reconstruct", str(DEMO / "a.dcm"), str(DEMO / "b.dcm"), "--seeds",
                   str(DEMO / "seeds.json"), "--out", str(tmp_path / "out"), "--quiet",
                   "--tracer", "3d")
    assert proc.returncode == 0, proc.stderr
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["tracer"]["kind"] == "3d"
    bad = run_cli("reconstruct", "--demo", "--out", str(tmp_path / "bad"), "--tracer", "4d")
    assert bad.returncode == 2 and "Traceback" not in bad.stderr


def test_cli_ends_on_different_vessels_exit_2_with_one_line(tmp_path) -> None:
    seeds = json.loads((DEMO / "seeds.json").read_text())
    seeds["segments"][0]["b"][-1][1] += 60.0
    path = tmp_path / "seeds.json"
    path.write_text(json.dumps(seeds))
    proc = run_cli("reconstruct", str(DEMO / "a.dcm"), str(DEMO / "b.dcm"), "--seeds",
                   str(path), "--out", str(tmp_path / "out"), "--quiet", "--tracer", "3d")
    assert_one_line_error(proc)
    assert not (tmp_path / "out" / "report.json").exists()
