"""`coronary3d bench intervals`: do the 95 % intervals contain the truth?

For each phantom case (preset ``PRESET_CYCLE[k % 4]``, seed ``seed + k``, diameter
stenosis drawn uniformly in :data:`STENOSIS_RANGE_PCT` from the case seed) the
whole ``reconstruct_pair`` runs (default options: the full calibration and
its intervals, :mod:`recon.pose.uncertainty`) and each figure's ``measurements_ci95``
is checked against the phantom's truth:

- ``mld_mm`` against the true MLD, ``reference_diameter_mm`` against the true
  reference diameter at the stenosis, ``diameter_stenosis_pct`` against the true
  % diameter stenosis, ``segment_length_mm`` against the true segment's length.

Reported: the coverage (share of cases whose interval holds the truth; the target
is 90-98 %), the median interval width, and the median |error| / (half-width /
1.96), the error in units of the interval's sd (1 would be a calibrated Gaussian;
above 1 the intervals are too narrow). Cases that fail to reconstruct are listed
with their reason and do not count. Each row also keeps the pipeline's own evidence
of unreliable stretches (the cross-view check's ``stretches``, the overlap stretches
per view, and the ``flagged_mm`` stretches the intervals drew as "that view is wrong
there"), so coverage can be read separately where the pipeline knew and where it
did not.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from recon.bench.common import PRESET_CYCLE, case_angiograms, median
from recon.pipeline import ReconstructionOptions, reconstruct_pair
from recon.synth import make_phantom

CASES = 200
STENOSIS_RANGE_PCT = (30.0, 70.0)
KEYS = ("mld_mm", "reference_diameter_mm", "diameter_stenosis_pct", "segment_length_mm")
TARGET_COVERAGE = (0.90, 0.98)
# The default pipeline (calibration "full"), but a coarse surface grid: the
# measurements come from the elliptic sections, not from the mesh, so only the
# (unused) mesh changes.
OPTIONS = ReconstructionOptions(voxel_mm=0.6)


def _stenosis_pct(case_seed: int) -> float:
    return float(np.random.default_rng([case_seed, 14]).uniform(*STENOSIS_RANGE_PCT))


def evaluate_case(job: tuple[str, int]) -> tuple[dict | None, dict | None]:
    """One case: (row, None) or (None, failure); runs in a worker."""
    preset, case_seed = job
    stenosis = _stenosis_pct(case_seed)
    try:
        case = make_phantom(preset, case_seed, stenosis_pct=stenosis)
        a, b = case_angiograms(case)
        t0 = time.perf_counter()
        rec = reconstruct_pair(a, b, case.seeds, OPTIONS)
        wall_ms = (time.perf_counter() - t0) * 1e3
    except ValueError as err:  # a failed case is a result, not a crash of the bench
        return None, {"preset": preset, "seed": case_seed, "error": str(err)}
    report = rec.report()
    truth = case.truth
    true = {
        "mld_mm": truth.mld_mm,
        "reference_diameter_mm": truth.reference_diameter_mm,
        "diameter_stenosis_pct": truth.stenosis_diameter_pct,
        "segment_length_mm": float(truth.segment_s_mm[-1] - truth.segment_s_mm[0]),
    }
    row: dict = {"preset": preset, "seed": case_seed, "stenosis_pct": stenosis,
                 "correction": report["calibration"]["correction"], "wall_ms": wall_ms,
                 "intervals_ms": report["timings_ms"].get("intervals"),
                 # the pipeline's own evidence of unreliable stretches
                 "stretches": (report["consistency"] or {}).get("stretches", []),
                 "overlap_mm": [report["centerline"]["overlap_a_mm"],
                                report["centerline"]["overlap_b_mm"]],
                 "flagged_mm": (report.get("uncertainty") or {}).get("flagged_mm")}
    for key in KEYS:
        lo, hi = report["measurements_ci95"][key]
        value = report["measurements"][key]
        half = 0.5 * (hi - lo)
        row[key] = {
            "value": value, "true": true[key], "lo": lo, "hi": hi,
            "covered": bool(lo <= true[key] <= hi), "width": hi - lo,
            "z": abs(value - true[key]) / (half / 1.959964) if half > 0 else float("inf"),
        }
    return row, None


def run(cases: int | None = None, seed: int = 0, workers: int | None = None,
        checkpoint: str | None = None) -> dict:
    """Coverage of the 95 % intervals on ``cases`` phantom cases (None: :data:`CASES`).

    ``workers``: the cases run in that many processes (None: in this process).
    ``checkpoint``: a JSON-lines file that gets each case's outcome as it finishes;
    cases already in it are not run again (a long run can be resumed, and read while
    it runs).
    """
    cases = CASES if cases is None else cases
    jobs = [(PRESET_CYCLE[k % len(PRESET_CYCLE)], seed + k) for k in range(cases)]
    done: dict[tuple[str, int], tuple[dict | None, dict | None]] = {}
    if checkpoint is not None and Path(checkpoint).exists():
        for line in Path(checkpoint).read_text().splitlines():
            row, failure = json.loads(line)
            item = row or failure
            done[(item["preset"], item["seed"])] = (row, failure)
    todo = [job for job in jobs if job not in done]
    t0 = time.perf_counter()

    def record(job: tuple[str, int], outcome: tuple[dict | None, dict | None]) -> None:
        done[job] = outcome
        if checkpoint is not None:
            with open(checkpoint, "a") as fh:
                fh.write(json.dumps(outcome, default=float) + "\n")

    if workers is None or workers <= 1 or len(todo) <= 1:
        for job in todo:
            record(job, evaluate_case(job))
    else:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor, as_completed

        with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as pool:
            futures = {pool.submit(evaluate_case, job): job for job in todo}
            for fut in as_completed(futures):
                record(futures[fut], fut.result())
    outcomes = [done[job] for job in jobs]
    return summarise(outcomes, time.perf_counter() - t0)


def summarise(outcomes: list[tuple[dict | None, dict | None]], elapsed_s: float = 0.0) -> dict:
    """The coverage figures of case outcomes ((row, None) or (None, failure) each)."""
    rows = [r for r, _ in outcomes if r is not None]
    failures = [f for _, f in outcomes if f is not None]
    if not rows:
        raise ValueError(f"bench intervals: all {len(outcomes)} cases failed, first: "
                         f"{failures[0]}")
    corrections = {c: sum(r["correction"] == c for r in rows)
                   for c in sorted({r["correction"] for r in rows})}
    return {
        "cases": len(rows),
        "failures": failures,
        "coverage": {k: float(np.mean([r[k]["covered"] for r in rows])) for k in KEYS},
        "median_width": {k: median(r[k]["width"] for r in rows) for k in KEYS},
        "median_abs_error": {k: median(abs(r[k]["value"] - r[k]["true"]) for r in rows)
                             for k in KEYS},
        "median_z": {k: median(r[k]["z"] for r in rows) for k in KEYS},
        "corrections": corrections,
        "target_coverage": list(TARGET_COVERAGE),
        "median_intervals_ms": median(r["intervals_ms"] for r in rows),
        "elapsed_s": elapsed_s,
        "rows": rows,
    }


def format_table(result: dict) -> str:
    """The coverage table (one line per figure)."""
    lines = [
        f"bench intervals: {result['cases']} cases ({len(result['failures'])} failed), "
        f"corrections chosen {result['corrections']}",
        f"{'figure':<24}{'coverage':>9}{'median width':>14}{'median |err|':>14}"
        f"{'median z':>10}",
    ]
    for k in KEYS:
        lines.append(f"{k:<24}{100 * result['coverage'][k]:>8.1f}%"
                     f"{result['median_width'][k]:>14.3f}{result['median_abs_error'][k]:>14.3f}"
                     f"{result['median_z'][k]:>10.2f}")
    lo, hi = result["target_coverage"]
    lines.append(f"target coverage {100 * lo:.0f}-{100 * hi:.0f} % (median z of a calibrated "
                 f"Gaussian interval: 0.67); intervals {result['median_intervals_ms']:.0f} ms "
                 "median per case")
    return "\n".join(lines)
