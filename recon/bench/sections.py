"""`coronary3d bench sections`: the elliptic section of an eccentric lumen from two widths.

Geometry only (no images, no tracing): for each case a lumen section with an
elliptic shape (axis ratio uniform in :data:`AXIS_RATIO_RANGE`, minor semi-axis
0.5-1.5 mm, random orientation in its plane), at a random point within 30 mm of
the isocenter with a random direction, seen by the two views of a preset
(``PRESET_CYCLE``). Each view's projected half-width is what it really is: the
ellipse's support (half caliper width) along that view's intersection line
(:func:`recon.lumen.surface.intersection_directions`). The section builder
(:func:`recon.lumen.surface.elliptic_cross_sections`) gets those two widths; its area
is compared with the truth per axis-ratio bin.

Two widths cannot fix an ellipse (three unknowns: two semi-axes and an
orientation). ``ambiguity`` measures how far apart the ellipses are that fit both
widths exactly, allowing any orientation and an axis ratio of at most
:data:`AMBIGUITY_MAX_RATIO` (an assumption about lesions, not a measured bound):
the median (max - min) / true area and the share of cases whose true area lies in
[min, max] (1 by construction when the truth's ratio is within the bound).
Lumens seen so nearly along one view's width line that the two lines are closer
than 10 degrees are not drawn (the builder falls back to a circle there).

Through rendered images (``images``; one case per 25 geometry cases): a straight
vessel with one elliptic stenosis (:mod:`recon.synth.elliptic_tube`; axis ratio
uniform in :data:`AXIS_RATIO_RANGE`, minor semi-axis 0.5-0.9 mm, random
orientation, lesion 8-16 mm long, round reference 1.2 x the major semi-axis,
1.4-2.8 mm) rendered into both views of a preset (true geometry, no header
error), traced (:func:`recon.trace.centerline.trace_segment`), matched and
triangulated; the section area at the lesion centre from the two calipers alone
and with the densitometric fill ratios (:mod:`recon.lumen.densitometry`), per bin.
"""


from __future__ import annotations

import numpy as np

from recon.bench.common import PRESET_CYCLE
from recon.errors import CoronaryError
from recon.lumen.surface import elliptic_cross_sections, intersection_directions
from recon.synth import PRESETS
from recon.types import Centerline3D

CASES = 3000
AXIS_RATIO_RANGE = (1.0, 2.5)
BINS = ((1.0, 1.5), (1.5, 2.0), (2.0, 2.5))
AMBIGUITY_MAX_RATIO = 2.5
_MIN_LINE_ANGLE_DEG = 10.0
_ORIENTATIONS = 1440


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _cases(rng: np.random.Generator, n: int, view_a, view_b) -> dict:
    """n sections (more drawn, the ill-conditioned ones dropped) with their true widths."""
    m = 3 * n
    X = rng.uniform(-30.0, 30.0, (m, 3))
    T = _unit(rng.standard_normal((m, 3)))
    la = intersection_directions(X, T, view_a)
    lb = intersection_directions(X, T, view_b)
    cos_ab = np.abs(np.einsum("ij,ij->i", la, lb))
    keep = np.flatnonzero(cos_ab < np.cos(np.deg2rad(_MIN_LINE_ANGLE_DEG)))[:n]
    X, T, la, lb = X[keep], T[keep], la[keep], lb[keep]
    k = len(keep)
    ratio = rng.uniform(*AXIS_RATIO_RANGE, k)
    b = rng.uniform(0.5, 1.5, k)
    a = ratio * b
    e1 = la  # in-plane frame (e1, e2) of each section
    e2 = np.cross(T, e1)
    phi = rng.uniform(0.0, np.pi, k)
    major = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2

    def support(line: np.ndarray) -> np.ndarray:
        c = np.einsum("ij,ij->i", line, major)
        return np.sqrt(a**2 * c**2 + b**2 * (1.0 - c**2))

    theta_b = np.arctan2(np.einsum("ij,ij->i", lb, e2), np.einsum("ij,ij->i", lb, e1))
    return {"X": X, "T": T, "w_a": support(la), "w_b": support(lb), "ratio": ratio,
            "area": np.pi * a * b, "theta_b": theta_b}


def feasible_area_range(w_a: np.ndarray, w_b: np.ndarray, theta_b: np.ndarray,
                        max_ratio: float = AMBIGUITY_MAX_RATIO) -> tuple[np.ndarray, np.ndarray]:
    """Smallest and largest area (N,) of the ellipses whose supports along directions 0
    and ``theta_b`` (N,) rad are w_a, w_b (N,), any orientation, axis ratio <= max_ratio.

    Per orientation phi of the major axis, h(t)^2 = A cos^2(t - phi) + B sin^2(t - phi)
    is linear in (A, B) = (a^2, b^2): a 2x2 solve on a grid of orientations. An
    orientation where the system is singular is skipped (e.g. for equal widths at right
    angles, the ellipses at 45 degrees: the range then misses them).
    """
    phi = np.linspace(0.0, np.pi, _ORIENTATIONS, endpoint=False)[:, None]
    ca, sa = np.cos(-phi) ** 2, np.sin(-phi) ** 2
    cb, sb = np.cos(theta_b - phi) ** 2, np.sin(theta_b - phi) ** 2
    det = ca * sb - sa * cb
    safe = np.where(np.abs(det) > 1e-9, det, 1.0)
    A = (w_a**2 * sb - w_b**2 * sa) / safe
    B = (ca * w_b**2 - cb * w_a**2) / safe
    ok = (np.abs(det) > 1e-9) & (A > 0) & (B > 0)
    ok &= np.maximum(A, B) <= max_ratio**2 * np.minimum(A, B)
    area = np.where(ok, np.pi * np.sqrt(np.abs(A * B)), np.nan)
    with np.errstate(invalid="ignore"):
        return np.nanmin(area, axis=0), np.nanmax(area, axis=0)


def run(cases: int | None = None, seed: int = 0) -> dict:
    """Area error of the section builder per axis-ratio bin, and the two-width ambiguity."""
    cases = CASES if cases is None else cases
    rng = np.random.default_rng(seed)
    per_preset = -(-cases // len(PRESET_CYCLE))
    err, ratio, lo_rel, hi_rel, inside = [], [], [], [], []
    for name in PRESET_CYCLE:
        preset = PRESETS[name]
        c = _cases(rng, per_preset, preset.view_a, preset.view_b)
        zeros = np.zeros((len(c["X"]), 2))
        cl = Centerline3D(X_world=c["X"], s_mm=np.arange(len(c["X"]), dtype=float),
                          tangents=c["T"], radius_a_mm=c["w_a"], radius_b_mm=c["w_b"],
                          X_raw_world=c["X"], points_a_px=zeros, points_b_px=zeros)
        area = elliptic_cross_sections(cl, preset.view_a, preset.view_b).area_mm2
        lo, hi = feasible_area_range(c["w_a"], c["w_b"], c["theta_b"])
        err.append(100.0 * (area / c["area"] - 1.0))
        ratio.append(c["ratio"])
        lo_rel.append(lo / c["area"])
        hi_rel.append(hi / c["area"])
        inside.append((c["area"] >= lo * (1 - 1e-6)) & (c["area"] <= hi * (1 + 1e-6)))
    err, ratio = np.concatenate(err)[:cases], np.concatenate(ratio)[:cases]
    lo_rel, hi_rel = np.concatenate(lo_rel)[:cases], np.concatenate(hi_rel)[:cases]
    inside = np.concatenate(inside)[:cases]
    bins = {}
    for lo_r, hi_r in BINS:
        m = (ratio >= lo_r) & (ratio < hi_r) if hi_r < BINS[-1][1] else (ratio >= lo_r)
        bins[f"{lo_r:.1f}-{hi_r:.1f}"] = {
            "cases": int(np.count_nonzero(m)),
            "median_abs_area_error_pct": float(np.median(np.abs(err[m]))),
            "median_area_error_pct": float(np.median(err[m])),
            "p90_abs_area_error_pct": float(np.percentile(np.abs(err[m]), 90)),
            "ambiguity_median_width_rel": float(np.nanmedian(hi_rel[m] - lo_rel[m])),
            "truth_in_ambiguity_range": float(np.mean(inside[m])),
        }
    return {
        "cases": int(len(err)),
        "bins": bins,
        "median_abs_area_error_pct": float(np.median(np.abs(err))),
        "target_median_abs_area_error_pct": 10.0,
        "ambiguity_max_ratio": AMBIGUITY_MAX_RATIO,
        "images": run_images(cases // _GEOMETRY_PER_IMAGE, seed),
    }


def format_table(result: dict) -> str:
    lines = [f"bench sections: {result['cases']} eccentric sections (geometry only), "
             f"median |area error| {result['median_abs_area_error_pct']:.1f} % (target at "
             f"most {result['target_median_abs_area_error_pct']:.0f} %)",
             f"{'axis ratio':<12}{'cases':>7}{'med |err| %':>13}{'med err %':>11}"
             f"{'p90 |err| %':>13}{'ambiguity':>11}{'truth in':>10}"]
    for name, b in result["bins"].items():
        lines.append(f"{name:<12}{b['cases']:>7}{b['median_abs_area_error_pct']:>13.1f}"
                     f"{b['median_area_error_pct']:>11.1f}{b['p90_abs_area_error_pct']:>13.1f}"
                     f"{b['ambiguity_median_width_rel']:>11.2f}"
                     f"{b['truth_in_ambiguity_range']:>10.2f}")
    lines.append(f"ambiguity: (max - min) / true area of the ellipses fitting both widths, "
                 f"any orientation, axis ratio <= {result['ambiguity_max_ratio']}")
    if result.get("images", {}).get("cases"):
        lines.append(format_images(result["images"]))
    return "\n".join(lines)


# ------------------------------------------------------------ through the images
#: Rendered cases per run (each renders two views and traces them: seconds, not ms).
IMAGE_CASES = 120
_IMAGE_MINOR_MM = (0.5, 0.9)
_MIN_SIN_ALPHA = 0.6
_LESION_MM = (8.0, 16.0)
#: One rendered case per this many geometry cases (``--cases 1500``: 60).
_GEOMETRY_PER_IMAGE = 25


def _draw_tube(rng: np.random.Generator, view_a, view_b):
    """A tube through the isocenter region seen well by both views (None: redraw)."""
    from recon.synth.elliptic_tube import EllipticTube

    X = rng.uniform(-12.0, 12.0, 3)
    T = _unit(rng.standard_normal(3))
    for view in (view_a, view_b):
        ray = _unit(X - view.source_world)
        if np.linalg.norm(np.cross(ray, T)) < _MIN_SIN_ALPHA:
            return None
    la = intersection_directions(X[None], T[None], view_a)[0]
    lb = intersection_directions(X[None], T[None], view_b)[0]
    if abs(float(la @ lb)) > np.cos(np.deg2rad(_MIN_LINE_ANGLE_DEG)):
        return None
    ratio = rng.uniform(*AXIS_RATIO_RANGE)
    b = rng.uniform(*_IMAGE_MINOR_MM)
    a = ratio * b
    e2 = np.cross(T, la)
    phi = rng.uniform(0.0, np.pi)
    major = np.cos(phi) * la + np.sin(phi) * e2
    tube = EllipticTube(centre_world=X, direction=T, major_dir=major,
                        ref_radius_mm=float(np.clip(1.2 * a, 1.4, 2.8)), major_mm=float(a),
                        minor_mm=float(b), lesion_length_mm=float(rng.uniform(*_LESION_MM)),
                        mu_per_mm=float(rng.uniform(0.085, 0.11)))
    for view in (view_a, view_b):
        uv = view.project(tube.axis_points(2))
        inside = (uv >= 30).all() and (uv[:, 0] <= view.cols - 30).all()
        if not (inside and (uv[:, 1] <= view.rows - 30).all()):
            return None
    return tube, ratio


def _image_case(rng: np.random.Generator, preset) -> dict | None:
    """One rendered eccentric lesion: areas at its centre, two-caliper and densitometric."""
    from recon.correspond.matching import match_centerlines
    from recon.correspond.triangulation import build_centerline_3d
    from recon.lumen.densitometry import with_fill_ratios
    from recon.synth.elliptic_tube import render_tube
    from recon.trace.centerline import compute_vesselness, trace_segment

    view_a, view_b = preset.view_a, preset.view_b
    drawn = None
    while drawn is None:
        drawn = _draw_tube(rng, view_a, view_b)
    tube, ratio = drawn
    ends = tube.centre_world[None] + np.array([[-1.0], [1.0]]) * (
        tube.half_length_mm - 3.0) * tube.direction[None]
    traces = []
    for view in (view_a, view_b):
        image = render_tube(rng, view, tube)
        pixel_mm = view.pixel_mm_at_isocenter
        vmap = compute_vesselness(image, pixel_mm=pixel_mm)
        traces.append(trace_segment(image, view.project(ends), vesselness=vmap,
                                    pixel_mm=pixel_mm))
    matching = match_centerlines(traces[0], traces[1], view_a, view_b)
    cl3d = build_centerline_3d(matching, view_a, view_b)
    i = int(np.argmin(np.linalg.norm(cl3d.X_world - tube.centre_world, axis=1)))
    two = elliptic_cross_sections(cl3d, view_a, view_b).area_mm2[i]
    dens_cl = with_fill_ratios(cl3d, view_a, view_b)
    dens = elliptic_cross_sections(dens_cl, view_a, view_b).area_mm2[i]
    return {"ratio": ratio, "area": tube.area_mm2, "two_caliper": float(two),
            "densitometric": float(dens), "calibrated": dens_cl.fill_a is not None}


def run_images(cases: int = IMAGE_CASES, seed: int = 0) -> dict:
    """Area error at the lesion centre through rendered images, per axis-ratio bin: the
    two-caliper section and the densitometric one, from the same traces."""
    rng = np.random.default_rng(seed + 1)
    rows, failures = [], 0
    for k in range(cases):
        preset = PRESETS[PRESET_CYCLE[k % len(PRESET_CYCLE)]]
        try:
            row = _image_case(rng, preset)
        except (ValueError, CoronaryError):
            failures += 1
            continue
        rows.append(row)
    if not rows:
        return {"cases": 0, "failed": failures, "bins": {}}
    ratio = np.array([r["ratio"] for r in rows])
    area = np.array([r["area"] for r in rows])
    err = {key: 100.0 * (np.array([r[key] for r in rows]) / area - 1.0)
           for key in ("two_caliper", "densitometric")}
    bins = {}
    for lo_r, hi_r in BINS:
        m = (ratio >= lo_r) & (ratio < hi_r) if hi_r < BINS[-1][1] else (ratio >= lo_r)
        if not np.any(m):
            continue
        bins[f"{lo_r:.1f}-{hi_r:.1f}"] = {
            "cases": int(np.count_nonzero(m)),
            **{f"median_abs_area_error_pct_{key}": float(np.median(np.abs(e[m])))
               for key, e in err.items()},
            **{f"median_area_error_pct_{key}": float(np.median(e[m])) for key, e in err.items()},
        }
    return {"cases": len(rows), "failed": failures, "bins": bins,
            "calibrated_share": float(np.mean([r["calibrated"] for r in rows])) if rows else 0.0,
            **{f"median_abs_area_error_pct_{key}": float(np.median(np.abs(e)))
               for key, e in err.items()}}


def format_images(result: dict) -> str:
    lines = [f"through rendered images: {result['cases']} eccentric lesions "
             f"({result['failed']} failed to trace), densitometry calibrated in "
             f"{100 * result['calibrated_share']:.0f} %; area at the lesion centre",
             f"{'axis ratio':<12}{'cases':>7}{'two-caliper med |err| %':>25}"
             f"{'densitometric med |err| %':>27}{'med err % (2-cal / dens)':>26}"]
    for name, b in result["bins"].items():
        lines.append(f"{name:<12}{b['cases']:>7}"
                     f"{b['median_abs_area_error_pct_two_caliper']:>25.1f}"
                     f"{b['median_abs_area_error_pct_densitometric']:>27.1f}"
                     f"{b['median_area_error_pct_two_caliper']:>14.1f} /"
                     f"{b['median_area_error_pct_densitometric']:>6.1f}")
    return "\n".join(lines)
