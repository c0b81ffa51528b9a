"""The guiding catheter: found where it enters the field, and kept off the trace."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import recon.trace.trace_path as trace_path
from recon.trace.centerline import trace_segment
from recon.trace.guide_catheter import Catheter2D, catheter_runs, find_catheters
from recon.trace.trace_error import TraceError
from recon.trace.vesselness import compute_vesselness
from tests.recon.trace.test_centerline import distance_to, render, segment

DATA = Path(__file__).resolve().parents[2] / "data"


def _shortcut_case(step: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A vessel (r 2.5 px) that leaves the catheter's tip, swings out in a half circle and
    crosses the catheter's shaft (r 3.5 px, from the top edge to its tip at row 150)
    before running left: up the catheter is a 90 px short cut. Returns the image, the
    clicks (on the half circle, and on the left), the vessel's and the catheter's
    centre lines. ``step``: a rib-like step edge across the background too."""
    t = np.linspace(0.0, np.pi, 4000)
    half = np.column_stack([130 + 47 * np.sin(t), 107 + 47 * np.cos(t)])
    vessel = np.vstack([half, segment((130, 60), (40, 60))])
    catheter = segment((130, -5), (130, 150))
    img = render((220, 260), [(vessel, np.full(len(vessel), 2.5)),
                              (catheter, np.full(len(catheter), 3.5))], noise=2.0)
    if step:
        rows = np.arange(220)[:, None]
        img = img * np.where(rows - 0.3 * np.arange(260)[None, :] > 40, 0.85, 1.0)
    clicks = np.array([[130 + 47 * np.sin(0.35), 107 + 47 * np.cos(0.35)], [50.0, 60.0]])
    return img, clicks, vessel, catheter


@pytest.mark.parametrize("step", [False, True])
def test_the_catheter_is_found_from_the_field_edge_to_its_tip_and_nothing_else(step: bool) -> None:
    img, clicks, vessel, catheter = _shortcut_case(step)
    found = find_catheters(compute_vesselness(img), img, clicks)
    assert len(found) == 1  # not the vessel, not the step edge
    cath = found[0]
    off = distance_to(cath.points_px, catheter)
    assert off.max() < 2.5 and np.median(off) < 1.0  # inside its lumen, near its centre
    assert cath.points_px[0][1] < 30  # enters at the top
    # ends near its tip (row 150), not past it: the track stops a few radii short where
    # the tip and the vessel leaving it merge into one blob
    assert 150 - 5 * 3.5 <= cath.tip_px[1] <= 154
    assert np.median(cath.radius_px) == pytest.approx(3.5, rel=0.45)


def test_the_trace_follows_the_vessel_not_the_catheter_short_cut(monkeypatch) -> None:
    img, clicks, vessel, catheter = _shortcut_case()
    vmap = compute_vesselness(img)
    cl = trace_segment(img, clicks, vesselness=vmap)
    assert distance_to(cl.points_px, vessel).max() < 1.0
    assert len(cl.catheters_px) == 1
    # without the cost along the catheter the route takes the short cut, and the check
    # names the place on the catheter and asks for a waypoint
    monkeypatch.setattr(trace_path, "_CATHETER_ALONG", 0.0)
    with pytest.raises(TraceError, match="runs along the guiding catheter") as err:
        trace_segment(img, clicks, vesselness=vmap)
    assert distance_to(np.atleast_2d(err.value.near_px), catheter).min() < 4.0
    assert "waypoint" in str(err.value)
    # a vessel that runs under the catheter in this view cannot be told from it there
    assert "runs under the catheter" in str(err.value) and "another view" in str(err.value)


def test_a_clicked_vessel_that_reaches_the_field_edge_is_not_a_catheter() -> None:
    line = segment((0, 40), (150, 40))
    img = render((80, 160), [(line, np.full(len(line), 3.0))], noise=2.0)
    clicks = np.array([[25.0, 40.0], [140.0, 40.0]])
    assert find_catheters(compute_vesselness(img), img, clicks) == ()
    cl = trace_segment(img, clicks)
    assert cl.catheters_px == ()


def test_runs_along_a_catheter_are_found_and_crossings_are_not() -> None:
    cath = Catheter2D(points_px=segment((50, 0), (50, 100), 101), radius_px=np.full(101, 3.0))
    along = np.vstack([segment((0, 20), (50, 20), 51), segment((50, 21), (50, 70), 50)])
    runs = catheter_runs(along, (cath,), min_run_px=12.0)
    assert len(runs) == 1
    i, j = runs[0]
    assert along[i][1] <= 22 and along[j - 1][1] >= 68
    across = segment((0, 50), (100, 50), 101)
    assert catheter_runs(across, (cath,), min_run_px=1.0) == []
    assert catheter_runs(along, (), min_run_px=1.0) == []


def test_the_catheter_of_a_real_clinical_frame_is_found() -> None:
    """Frame 40 of the clinical cine (no pixel size in its header): the guiding catheter,
    read by eye as the darkest column of the smoothed image, runs from (262, 15) to
    (244, 90) and into the right coronary ostium near row 100."""
    pydicom = pytest.importorskip("pydicom")
    frame = pydicom.dcmread(DATA / "rca-cine-ecg.dcm").pixel_array[40].astype(np.float32)
    clicks = np.array([[180.0, 140.0], [120.0, 300.0]])  # on the proximal and mid RCA
    found = find_catheters(compute_vesselness(frame), frame, clicks)
    assert len(found) == 1
    cath = found[0]
    by_eye = segment((262, 15), (240, 105))
    assert distance_to(cath.points_px, by_eye).max() < 4.0
    assert cath.points_px[0][1] < 40 and cath.tip_px[1] > 85
