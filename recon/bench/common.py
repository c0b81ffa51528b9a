"""What the benchmarks share: the preset cycle, the true-pose error of a view, the suites.

The pose error compares a view's rigid rig correction with the true one
(:meth:`recon.geometry.ViewGeometry.with_correction`: the rig maps its own
frame into the world by ``x -> R_corr x + t_corr``):

- rotation: the angle of ``R_est R_true^T``;
- displacement: the mean distance the given world points move under the
  rig error, i.e. the motion ``T_est T_true^-1`` that carries the true rig
  onto the estimated one: a point fixed to the true rig at X lands at
  ``R_est R_true^T (X - t_true) + t_est``. This is how far the points move
  relative to the view's rig, so how far their rays are off.

For the varied suite (:func:`recon.synth.suites.varied_cases`): the
in-memory angiogram a chain's file would give (:func:`case_angiogram`),
jittered clicks (:func:`jitter_seeds`), the RMS after a rigid alignment to
the truth (:func:`rigid_rms_mm`) and a small process pool
(:func:`parallel_map`), and the body of a per-chain table (:func:`varied_rows`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from recon.geometry import ViewGeometry, rotvec_from_rotation
from recon.synth import PhantomCase
from recon.types import Angiogram

__all__ = [
    "PRESET_CYCLE",
    "pose_error",
    "SUITES",
    "VARIED_CASES_PER_CHAIN",
    "check_suite",
    "case_angiogram",
    "jitter_seeds",
    "rigid_rms_mm",
    "parallel_map",
    "median",
    "percentile",
    "varied_rows",
]

#: The presets a benchmark cycles through, case k using PRESET_CYCLE[k % 4].
PRESET_CYCLE = ("data1", "data2", "data3", "static")


def pose_error(
    view_est: ViewGeometry, view_true: ViewGeometry, X_world: ArrayLike
) -> tuple[float, float]:
    """(rotation error deg, mean displacement mm of X_world (P, 3)) of ``view_est``'s rig."""
    X_world = np.asarray(X_world, dtype=float)
    R_err = view_est.R_corr @ view_true.R_corr.T
    t_est = np.asarray(view_est.t_corr_mm)
    t_true = np.asarray(view_true.t_corr_mm)
    moved = (X_world - t_true) @ R_err.T + t_est
    rotation_deg = float(np.degrees(np.linalg.norm(rotvec_from_rotation(R_err))))
    displacement_mm = float(np.mean(np.linalg.norm(moved - X_world, axis=1)))
    return rotation_deg, displacement_mm


# ------------------------------------------------------------ the varied suite
#: The suites a bench takes: "regular" (the plain phantom, PRESET_CYCLE) and
#: "varied" (recon.synth.suites.varied_cases: imaging chains x harder anatomy).
SUITES = ("regular", "varied")
#: Cases per chain of the varied suite when run(cases=None).
VARIED_CASES_PER_CHAIN = 8
#: Largest worker processes a varied bench uses (the CI machine has 2 cores).
MAX_WORKERS = 2


def check_suite(suite: str) -> None:
    """ValueError unless ``suite`` is one of :data:`SUITES`."""
    if suite not in SUITES:
        raise ValueError(f"unknown suite {suite!r} (use one of {', '.join(SUITES)})")


def case_angiogram(image: np.ndarray, view: ViewGeometry, name: str, chain=None):
    """An in-memory :class:`recon.types.Angiogram` of a phantom image.

    ``chain`` (a :class:`recon.synth.chains.ChainDraw` or None) fills
    ``info`` the way a file of that chain would: its
    PixelIntensityRelationship tag and bits stored. The plain phantom's
    angiogram has an empty ``info``, as before.
    """
    from recon.types import Angiogram

    info = {}
    if chain is not None:
        info = {"pixel_intensity_relationship": chain.tag, "bits_stored": chain.bits_stored}
    return Angiogram(image=np.asarray(image, dtype=np.float32), geometry=view, path=name,
                     frame_index=0, frame_reason="single frame", n_frames=1,
                     frame_time_ms=None, frames=None, geometry_notes=(), info=info)


def jitter_seeds(seeds, rng: np.random.Generator, radius_px: float,
                 shape_a: tuple[int, int], shape_b: tuple[int, int]):
    """The seeds with every click moved uniformly within a disc of ``radius_px``.

    Segment clicks and features in both views; clicks stay inside the image
    ((H, W) ``shape_a`` / ``shape_b``) and are rounded to 0.1 px as stored
    clicks are.
    """
    from recon.seeds import Feature, Seeds, Segment

    def move(points, shape) -> tuple[tuple[float, float], ...]:
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        r = radius_px * np.sqrt(rng.uniform(size=len(p)))
        phi = rng.uniform(0.0, 2 * np.pi, len(p))
        q = p + np.column_stack([r * np.cos(phi), r * np.sin(phi)])
        q[:, 0] = np.clip(q[:, 0], 0.0, shape[1] - 1.0)
        q[:, 1] = np.clip(q[:, 1], 0.0, shape[0] - 1.0)
        return tuple((round(float(c), 1), round(float(w), 1)) for c, w in q)

    segments = tuple(Segment(s.name, move(s.a_px, shape_a), move(s.b_px, shape_b))
                     for s in seeds.segments)
    features = tuple(Feature(f.name, move([f.a_px], shape_a)[0], move([f.b_px], shape_b)[0])
                     for f in seeds.features)
    return Seeds(segments=segments, features=features)


def _kabsch(P: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R and translation t minimising |R P_i + t - Q_i|^2 (rigid, no scale)."""
    cp, cq = P.mean(axis=0), Q.mean(axis=0)
    U, _, Vt = np.linalg.svd((P - cp).T @ (Q - cq))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, cq - R @ cp


def _closest_on_polyline(Y: np.ndarray, dense: np.ndarray, tree) -> np.ndarray:
    """Closest points (N, 3) of the polyline ``dense`` (M, 3) to Y (N, 3).

    The nearest vertex (``tree``: a cKDTree of ``dense``), then the foot
    points on its two adjacent pieces, whichever is nearer.
    """
    _, idx = tree.query(Y)
    best = dense[idx]
    best_d = np.linalg.norm(Y - best, axis=1)
    for lo in (idx - 1, idx):
        lo = np.clip(lo, 0, len(dense) - 2)
        a, b = dense[lo], dense[lo + 1]
        ab = b - a
        t = np.clip(np.sum((Y - a) * ab, axis=1) / np.maximum(np.sum(ab * ab, axis=1), 1e-18),
                    0.0, 1.0)
        foot = a + t[:, None] * ab
        d = np.linalg.norm(Y - foot, axis=1)
        closer = d < best_d
        best[closer], best_d[closer] = foot[closer], d[closer]
    return best


def rigid_rms_mm(X: np.ndarray, truth: np.ndarray, iterations: int = 50) -> float:
    """3D RMS distance (mm) of X (N, 3) from the truth polyline (M, 3) after a rigid alignment.

    Rotation and translation only (no scale): started from arc-length
    correspondence (both run proximal to distal), refined by iterated
    closest points on the truth polyline.
    """
    from scipy.spatial import cKDTree

    from recon.types import arclength

    X = np.asarray(X, dtype=float)
    truth = np.asarray(truth, dtype=float)
    s_t = arclength(truth)
    tree = cKDTree(truth)
    s_x = arclength(X)
    frac = s_x / max(s_x[-1], 1e-9)
    target = np.column_stack([np.interp(frac * s_t[-1], s_t, truth[:, k]) for k in range(3)])
    R, t = _kabsch(X, target)
    for _ in range(iterations):
        R_new, t_new = _kabsch(X, _closest_on_polyline(X @ R.T + t, truth, tree))
        done = np.allclose(R_new, R, atol=1e-10) and np.allclose(t_new, t, atol=1e-8)
        R, t = R_new, t_new
        if done:
            break
    Y = X @ R.T + t
    d = np.linalg.norm(Y - _closest_on_polyline(Y, truth, tree), axis=1)
    return float(np.sqrt(np.mean(d**2)))


def parallel_map(fn, items: list, workers: int | None = None) -> list:
    """``[fn(x) for x in items]`` in up to :data:`MAX_WORKERS` processes, in order.

    ``fn`` must be a module-level function (it is pickled); one item or one
    core runs in this process.
    """
    import os

    n = min(MAX_WORKERS if workers is None else workers, os.cpu_count() or 1, len(items))
    if n <= 1:
        return [fn(x) for x in items]
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=n, mp_context=mp.get_context("fork")) as pool:
        return list(pool.map(fn, items, chunksize=1))


def median(values) -> float:
    """Median of finite values (NaN when there are none)."""
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], dtype=float)
    return float(np.median(v)) if len(v) else float("nan")


def percentile(values, q: float) -> float:
    """q-th percentile of finite values (NaN when there are none)."""
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], dtype=float)
    return float(np.percentile(v, q)) if len(v) else float("nan")


def varied_rows(result: dict, line: Callable[[str, dict], str], rule: str) -> list[str]:
    """The body of a varied-suite table: a ``line`` per chain, ``rule``, the overall
    line, then a line per anatomy variant, and a blank line."""
    rows = [line(name, f) for name, f in result["chains"].items()]
    rows += [rule, line("overall", result["overall"]), "", "by anatomy"]
    rows += [line(name, f) for name, f in result["anatomy"].items()]
    return [*rows, ""]


def _angiogram(image: np.ndarray, view: ViewGeometry, name: str) -> Angiogram:
    return Angiogram(
        image=image.astype(np.float32),
        geometry=view,
        path=name,
        frame_index=0,
        frame_reason="single frame",
        n_frames=1,
        frame_time_ms=None,
        frames=None,
        geometry_notes=(),
        info={},
    )


def polyline_distance_mm(points: np.ndarray, truth_dense: np.ndarray) -> np.ndarray:
    """Distance (N,) from points (N, 3) to a densely sampled polyline (M, 3)."""
    dist, _ = cKDTree(truth_dense).query(points)
    return dist


def scale_free_rms_mm(X_world: np.ndarray, truth_dense: np.ndarray, source_a: np.ndarray
                      ) -> tuple[float, float]:
    """3D RMS error after the best scaling about view A's source, and that scale.

    Two views fix view B's pose only up to the length of the baseline (moving
    B's rig along the line between the sources changes no epipolar line), so
    a reconstruction is determined up to a scaling about A's source: this is
    the error that remains once that unobservable factor is removed.
    """
    from scipy.optimize import minimize_scalar

    tree = cKDTree(truth_dense)

    def rms(k: float) -> float:
        d, _ = tree.query(source_a + k * (X_world - source_a))
        return float(np.sqrt(np.mean(d**2)))

    res = minimize_scalar(rms, bounds=(0.9, 1.1), method="bounded",
                          options={"xatol": 1e-6})
    return float(res.fun), float(res.x)


def case_angiograms(case: PhantomCase) -> tuple[Angiogram, Angiogram]:
    """View A (true = header geometry) and view B (header geometry) as angiograms.

    A chain's case carries its tag and bits stored in ``info`` (see
    :func:`recon.bench.common.case_angiogram`); a plain case has none.
    """
    if case.chain is None:
        return (_angiogram(case.image_a, case.view_a, f"{case.preset}-{case.seed}-a"),
                _angiogram(case.image_b, case.view_b_nominal, f"{case.preset}-{case.seed}-b"))
    return (case_angiogram(case.image_a, case.view_a, f"{case.preset}-{case.seed}-a", case.chain),
            case_angiogram(case.image_b, case.view_b_nominal, f"{case.preset}-{case.seed}-b",
                           case.chain))


def scale_free_error_mm(X_rec, X_true, source_a) -> tuple[float, float]:
    """RMS distance (mm) of X_rec (P, 3) from its counterparts X_true (P, 3) after the
    best scaling about view A's source ``source_a`` (3,), and that scale (closed form)."""
    a = np.asarray(X_rec) - source_a
    b = np.asarray(X_true) - source_a
    k = float(np.sum(a * b) / np.sum(a * a))
    return float(np.sqrt(np.mean(np.sum((k * a - b) ** 2, axis=1)))), k
