"""`coronary3d bench centerline`: 2D tracing against the phantom's projected truth.

For each synthetic case (several presets and seeds) and each view (A, and B
with its TRUE geometry), the segment is traced from the phantom's noisy clicks
and compared with the true projected main vessel:

- centerline_rms_px: RMS distance from every traced point to the nearest
  point of the true projected centerline of the main vessel (densely
  resampled to 0.02 px, so the discretisation error is negligible);
- radius_mae_px: mean |traced radius - true radius| where the true radius is
  r_mm SID / depth / spacing at the nearest true point; the first and last
  3 px of arc length of the trace are excluded (the profile there may reach
  past the clicked end);
- vesselness_ms: time of :func:`compute_vesselness` on one whole image;
- trace_ms: time of :func:`trace_segment` for the segment, given the vesselness.

Summary figures are medians over cases and both views.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial import cKDTree

from recon.bench.common import PRESET_CYCLE
from recon.centerline import compute_vesselness, trace_segment
from recon.geometry import ViewGeometry
from recon.synth import make_phantom
from recon.types import arclength

__all__ = ["run", "format_table", "PRESET_CYCLE", "END_EXCLUSION_PX", "CASES"]

CASES = 10  # phantom cases when run(cases=None)
#: Arc length (px) left out of the radius error at both ends of each trace.
END_EXCLUSION_PX = 3.0


def _dense_truth(
    view: ViewGeometry, X_world: np.ndarray, radius_mm: np.ndarray, step_px: float = 0.02
) -> tuple[np.ndarray, np.ndarray]:
    """True projected centerline (M, 2) resampled every ``step_px``, and radius (M,) px."""
    pts = view.project(X_world)
    depth = view.depth_mm(X_world)
    radius_px = radius_mm * view.sid_mm / depth / float(np.mean(view.pixel_spacing_mm))
    s = arclength(pts)
    s_new = np.arange(0.0, s[-1], step_px)
    dense = np.column_stack([np.interp(s_new, s, pts[:, 0]), np.interp(s_new, s, pts[:, 1])])
    return dense, np.interp(s_new, s, radius_px)


def _evaluate_view(
    image: np.ndarray, view: ViewGeometry, clicks_px: np.ndarray, truth_X: np.ndarray,
    truth_r_mm: np.ndarray, name: str,
) -> dict:
    t0 = time.perf_counter()
    vmap = compute_vesselness(image)
    t1 = time.perf_counter()
    cl = trace_segment(image, clicks_px, vesselness=vmap, view=name)
    t2 = time.perf_counter()
    dense, radius_true = _dense_truth(view, truth_X, truth_r_mm)
    dist, nearest = cKDTree(dense).query(cl.points_px)
    s = cl.arclength_px
    inner = (s >= END_EXCLUSION_PX) & (s <= s[-1] - END_EXCLUSION_PX)
    err_r = cl.radius_px[inner] - radius_true[nearest[inner]]
    return {
        "view": name,
        "n_points": int(len(cl.points_px)),
        "length_px": float(cl.length_px),
        "centerline_rms_px": float(np.sqrt(np.mean(dist**2))),
        "centerline_max_px": float(dist.max()),
        "radius_mae_px": float(np.mean(np.abs(err_r))),
        "radius_bias_px": float(np.mean(err_r)),
        "radius_true_median_px": float(np.median(radius_true[nearest])),
        "vesselness_ms": 1e3 * (t1 - t0),
        "trace_ms": 1e3 * (t2 - t1),
    }


def run(cases: int | None = None, seed: int = 0) -> dict:
    """Trace the phantom segment in both views of ``cases`` cases.

    Parameters
    ----------
    cases : number of phantom cases (None: :data:`CASES`); presets cycle
        through :data:`PRESET_CYCLE`.
    seed : seed of the first case (case k uses seed + k).

    Returns
    -------
    dict with "cases", the medians "centerline_rms_px", "radius_mae_px",
    "vesselness_ms", "trace_ms" (over cases and both views), "rows" (one per
    case and view), "failures" (traces that raised) and "notes".
    """
    cases = CASES if cases is None else cases
    rows: list[dict] = []
    failures: list[dict] = []
    for k in range(cases):
        preset = PRESET_CYCLE[k % len(PRESET_CYCLE)]
        case = make_phantom(preset, seed + k, render=True)
        segment = case.seeds.segments[0]
        main_X, main_r = case.truth.vessels[0]  # the whole main vessel: traces may run past
        for name, image, view, clicks in (
            ("A", case.image_a, case.view_a, segment.a),
            ("B", case.image_b, case.view_b_true, segment.b),
        ):
            try:
                row = _evaluate_view(image, view, clicks, main_X, main_r, name)
            except ValueError as err:
                failures.append({"preset": preset, "seed": seed + k, "view": name,
                                 "error": str(err)})
                continue
            rows.append({"preset": preset, "seed": seed + k, **row})

    def med(key: str) -> float:
        return float(np.median([r[key] for r in rows])) if rows else float("nan")

    return {
        "cases": int(cases),
        "traces": len(rows),
        "centerline_rms_px": med("centerline_rms_px"),
        "radius_mae_px": med("radius_mae_px"),
        "radius_bias_px": med("radius_bias_px"),
        "vesselness_ms": med("vesselness_ms"),
        "trace_ms": med("trace_ms"),
        "targets": {"centerline_rms_px": 0.3, "radius_mae_px": 0.3,
                    "vesselness_ms": 500.0, "trace_ms": 50.0},
        "rows": rows,
        "failures": failures,
        "notes": (
            "medians over cases and both views; distances to the densely resampled true "
            "projected main vessel; radius error excludes the first and last "
            f"{END_EXCLUSION_PX:g} px of each trace"
        ),
    }


def format_table(result: dict) -> str:
    """Plain-text table of a :func:`run` result: one line per trace, then the medians."""
    head = (f"{'preset':<8}{'seed':>5}{'view':>5}{'len px':>8}{'rms px':>8}{'max px':>8}"
            f"{'r MAE':>7}{'r bias':>8}{'r px':>6}{'vess ms':>9}{'trace ms':>9}")
    lines = ["centerline benchmark: traced vs true projected centerline", head,
             "-" * len(head)]
    for r in result["rows"]:
        lines.append(
            f"{r['preset']:<8}{r['seed']:>5}{r['view']:>5}{r['length_px']:>8.0f}"
            f"{r['centerline_rms_px']:>8.3f}{r['centerline_max_px']:>8.2f}"
            f"{r['radius_mae_px']:>7.3f}{r['radius_bias_px']:>8.3f}"
            f"{r['radius_true_median_px']:>6.1f}{r['vesselness_ms']:>9.0f}{r['trace_ms']:>9.1f}"
        )
    for f in result["failures"]:
        lines.append(f"{f['preset']:<8}{f['seed']:>5}{f['view']:>5}  FAILED: {f['error']}")
    lines.append("-" * len(head))
    t = result["targets"]
    for key, unit in (("centerline_rms_px", "px"), ("radius_mae_px", "px"),
                      ("vesselness_ms", "ms"), ("trace_ms", "ms")):
        ok = "ok" if result[key] <= t[key] else "MISSED"
        lines.append(f"median {key:<18} {result[key]:8.3f} {unit}  (target <= {t[key]:g}: {ok})")
    lines.append(f"{result['traces']} traces from {result['cases']} cases; {result['notes']}")
    return "\n".join(lines)
