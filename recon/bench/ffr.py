"""`coronary3d bench ffr`: the FFR model's analytic checks, then the FFR of the
reconstruction against the same model on the phantom's true lumen.

**Analytic** (:func:`analytic`): the model (:mod:`recon.lumen.ffr`, flows by svZeroDSolver)
on exact lumens, no reconstruction.

- A straight tube (radius :data:`TUBE_RADIUS_MM`, :data:`TUBE_LENGTH_MM`): the pressure
  drop at the solved flow against Poiseuille's 8 mu L Q / (pi r^4) at that flow, and the
  flow against the closed form Pa / (R + 8 mu L / (pi r^4)); both within
  :data:`TUBE_TOLERANCE`.
- A single axisymmetric raised-cosine narrowing r = r0 (1 - p (1 + cos(2 pi x / Ls)) / 2)
  of each severity of :data:`NARROWING_PCT` in the same tube: the drop against the model's
  own closed form, within :data:`NARROWING_TOLERANCE`. Closed form: the viscous coefficient
  over the narrowing is (Ls / 2 pi) 8 pi mu I4 / (pi r0^2)^2 with
  I4 = pi al (2 al^2 + 3 be^2) / (al^2 - be^2)^(7/2), al = 1 - p / 2, be = p / 2 (the
  integral of (al - be cos t)^-4 over a period), the separation coefficient
  (Kt / 2) rho (A0 / Amin - 1)^2 / A0^2, and the flow the root of
  b Q^2 + (a + R) Q - Pa = 0.

**Geometry error to FFR error**: phantom cases of the regular suite (presets cycled as in
``bench reconstruct``, seeds ``seed + k``) and of the varied suite
(:func:`recon.synth.suites.varied_cases` at ``seed``), each with its own diameter stenosis
drawn uniformly from :data:`STENOSIS_PCT_RANGE` (seeded by the case; the other benches keep
their fixed 50 %, which puts most true FFRs just above 0.80). Each case is reconstructed
(``reconstruct_pair``, default options) and its distal FFR compared with the FFR the same
model computes from the phantom's true lumen (areas pi r^2 along the true segment, through
the same profile and reference fit, :func:`recon.lumen.measure.lumen_profile`). Figures
overall, per suite and per imaging chain: ``ffr_abs_err_median``, ``ffr_abs_err_p90``,
``ffr_ci95_coverage`` (the true FFR inside the reported 95 % interval),
``ffr_decision_agreement`` (FFR < :data:`CUTOFF` on both or neither) and
``true_below_cutoff_fraction``; a case whose reconstruction failed is counted apart.

**Where the error comes from** (:func:`error_parts`): each case's distal FFR error split
over the model's three numbers, the distal resistance R (through A_ref), the viscous
coefficient a and the separation coefficient b (:func:`recon.lumen.ffr.vessel_coefficients`),
by their Shapley values: the mean, over the orders in which the three are changed from
the true lumen's to the reconstruction's, of the FFR change each one makes. The three sum
to the error (of the one-vessel closed form, equal to the solver's to about 1e-9). Per
group: the median |part| and, among the cases whose |error| exceeds the p90 target, which
part is the largest.
"""

from __future__ import annotations

import time

import numpy as np

from recon.bench.common import PRESET_CYCLE, case_angiograms, median, parallel_map, percentile
from recon.lumen.ffr import (
    MMHG_PA,
    FFRModel,
    FFRVessel,
    Lumen,
    distal_ffr,
    tree_ffr,
    vessel_coefficients,
    vessel_ffr,
)
from recon.lumen.measure import lumen_profile
from recon.pipeline import ReconstructionOptions, reconstruct_pair
from recon.synth import make_phantom

CASES = 8  # regular-suite cases when run(cases=None)
VARIED_PER_CHAIN = 8  # varied-suite cases per imaging chain when run(cases=None)
STENOSIS_PCT_RANGE = (35.0, 75.0)  # each case's diameter stenosis, uniform (docs/ffr.md: why)
CUTOFF = 0.80  # the FFR decision threshold
TUBE_RADIUS_MM = 1.5
TUBE_LENGTH_MM = 40.0
STEP_MM = 0.1
NARROWING_LENGTH_MM = 10.0
NARROWING_PCT = (30.0, 50.0, 70.0, 80.0)
TUBE_TOLERANCE = 0.005
NARROWING_TOLERANCE = 0.01
TARGETS = {"ffr_abs_err_median": 0.01, "ffr_abs_err_p90": 0.03,
           "ffr_ci95_coverage": (0.90, 0.98), "ffr_decision_agreement": 0.95,
           "true_below_cutoff_fraction": 1.0 / 3.0}


def _tube(radius_mm: np.ndarray, s_mm: np.ndarray, reference_mm: float) -> FFRVessel:
    area = np.pi * radius_mm**2
    return FFRVessel(Lumen(s_mm, area, np.full_like(area, np.pi * reference_mm**2)))


def _si_area(radius_mm: float) -> float:
    return np.pi * (radius_mm * 1e-3) ** 2


def analytic(model: FFRModel | None = None) -> dict:
    """The straight tube and the single narrowing against their closed forms (module
    docstring); relative errors and pass flags."""
    model = model or FFRModel()
    pa = model.aortic_pressure_mmhg
    mu, rho = model.viscosity_pa_s, model.density_kg_m3
    s = np.arange(0.0, TUBE_LENGTH_MM + STEP_MM / 2, STEP_MM)
    r0 = TUBE_RADIUS_MM
    a0_m2 = _si_area(r0)
    resistance = pa / (model.velocity_m_s * np.pi * r0**2)  # mmHg s / mL (A in mm^2)
    to_mmhg_ml = 1e-6 / MMHG_PA

    tube = tree_ffr([_tube(np.full_like(s, r0), s, r0)], model)[0]
    q = tube.flow_ml_s
    drop = pa * (1.0 - tube.distal)
    poiseuille = 8.0 * mu * TUBE_LENGTH_MM * 1e-3 / (np.pi * (r0 * 1e-3) ** 4) * to_mmhg_ml
    tube_row = {"radius_mm": r0, "length_mm": TUBE_LENGTH_MM, "flow_ml_s": q,
                "drop_mmhg": drop, "poiseuille_drop_mmhg": poiseuille * q,
                "rel_err": abs(drop - poiseuille * q) / (poiseuille * q),
                "flow_closed_form_ml_s": pa / (resistance + poiseuille),
                "flow_rel_err": abs(q - pa / (resistance + poiseuille))
                / (pa / (resistance + poiseuille))}
    tube_row["pass"] = bool(max(tube_row["rel_err"], tube_row["flow_rel_err"]) <= TUBE_TOLERANCE)

    rows = []
    centre = TUBE_LENGTH_MM / 2
    x = (s - centre) / NARROWING_LENGTH_MM
    bump = np.where(np.abs(x) < 0.5, 0.5 * (1.0 + np.cos(2.0 * np.pi * x)), 0.0)
    for pct in NARROWING_PCT:
        p = pct / 100.0
        result = tree_ffr([_tube(r0 * (1.0 - p * bump), s, r0)], model)[0]
        al, be = 1.0 - p / 2.0, p / 2.0
        i4 = np.pi * al * (2 * al**2 + 3 * be**2) / (al**2 - be**2) ** 3.5
        ls = NARROWING_LENGTH_MM * 1e-3
        a_si = 8.0 * np.pi * mu / a0_m2**2 * ((TUBE_LENGTH_MM * 1e-3 - ls)
                                                 + ls / (2.0 * np.pi) * i4)
        a = a_si * to_mmhg_ml
        b = 0.5 * model.kt * rho * (1.0 / (1.0 - p) ** 2 - 1.0) ** 2 / a0_m2**2 \
            * 1e-12 / MMHG_PA
        q = 2.0 * pa / ((a + resistance) + np.sqrt((a + resistance) ** 2 + 4.0 * b * pa))
        closed = a * q + b * q**2
        drop = pa * (1.0 - result.distal)
        rows.append({"stenosis_pct": pct, "drop_mmhg": drop, "closed_form_drop_mmhg": closed,
                     "ffr": result.distal, "closed_form_ffr": 1.0 - closed / pa,
                     "rel_err": abs(drop - closed) / closed})
    worst = max(r["rel_err"] for r in rows)
    return {"straight_tube": tube_row,
            "narrowing": {"length_mm": NARROWING_LENGTH_MM, "cases": rows,
                          "max_rel_err": worst, "pass": bool(worst <= NARROWING_TOLERANCE)},
            "tolerances": {"straight_tube": TUBE_TOLERANCE, "narrowing": NARROWING_TOLERANCE}}


def _true_profile(truth):
    return lumen_profile(truth.segment_s_mm, np.pi * truth.segment_radius_mm**2)


def true_ffr(truth, model: FFRModel | None = None) -> float:
    """The model's distal FFR on the phantom's true segment lumen (areas pi r^2)."""
    return vessel_ffr(_true_profile(truth), (), model).distal


PARTS = ("resistance", "viscous", "separation")


def error_parts(rec: tuple[float, float, float], true: tuple[float, float, float],
                aortic_pressure_mmhg: float) -> dict[str, float]:
    """The distal FFR error of (R, a, b) ``rec`` against ``true`` split over the three by
    their Shapley values (module docstring); the values sum to the error."""
    out = dict.fromkeys(PARTS, 0.0)
    orders = ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0))
    for order in orders:
        now = list(true)
        before = distal_ffr(*now, aortic_pressure_mmhg)
        for i in order:
            now[i] = rec[i]
            after = distal_ffr(*now, aortic_pressure_mmhg)
            out[PARTS[i]] += (after - before) / len(orders)
            before = after
    return out


def case_stenosis_pct(seed: int, k: int) -> float:
    """Case k's diameter stenosis (%): uniform over :data:`STENOSIS_PCT_RANGE`."""
    return float(np.random.default_rng([int(seed), 47, int(k)]).uniform(*STENOSIS_PCT_RANGE))


def _case_job(job) -> dict:
    """One case (runs in a worker): its row, or its failure."""
    suite, which, pct = job
    if suite == "regular":
        preset, case_seed = which
        case = make_phantom(preset, case_seed, stenosis_pct=pct)
        key = {"suite": "regular", "chain": "regular", "preset": preset, "seed": case_seed,
               "anatomy": "plain"}
    else:
        from recon.synth.suites import make_suite_case

        case = make_suite_case(which, stenosis_pct=pct)
        key = {"suite": "varied", "chain": which.chain, "preset": which.preset_name,
               "seed": which.seed, "anatomy": which.anatomy}
    key["stenosis_pct"] = pct
    model = FFRModel()
    true_lumen = Lumen.from_profile(_true_profile(case.truth))
    truth = true_ffr(case.truth, model)
    a, b = case_angiograms(case)
    try:
        rec = reconstruct_pair(a, b, case.seeds, ReconstructionOptions())
    except ValueError as err:  # CoronaryError included: a failed case is a result
        return {"row": None, "failure": {**key, "ffr_true": truth,
                                         "error": " ".join(str(err).split())}}
    ffr = rec.ffr
    ci = ffr.ci95
    rec_lumen = Lumen.from_profile(rec.profile)
    coeffs = vessel_coefficients(rec_lumen, model)
    true_coeffs = vessel_coefficients(true_lumen, model)
    parts = error_parts(coeffs, true_coeffs, model.aortic_pressure_mmhg)
    row = {**key, "ffr_true": truth, "ffr": ffr.distal, "ffr_error": ffr.distal - truth,
           "ffr_ci95": list(ci) if ci is not None else None,
           "covered": None if ci is None else bool(ci[0] <= truth <= ci[1]),
           "decision_agrees": bool((ffr.distal < CUTOFF) == (truth < CUTOFF)),
           "flow_band": list(ffr.flow_band),
           "mld_error_mm": rec.measurements.mld_mm - case.truth.mld_mm,
           "ffr_error_parts": parts,
           "a_ref_mm2": [rec_lumen.inlet_area_mm2(model.reference_length_mm, model.inlet_area),
                         true_lumen.inlet_area_mm2(model.reference_length_mm, model.inlet_area)],
           "ffr_ms": rec.timings_ms.get("ffr")}
    return {"row": row, "failure": None}


def figures(rows: list[dict], failures: list[dict]) -> dict:
    """The FFR figures of a set of cases (rows ran, failures did not)."""
    err = [abs(r["ffr_error"]) for r in rows]
    covered = [r["covered"] for r in rows if r["covered"] is not None]
    truths = [r["ffr_true"] for r in rows] + [f["ffr_true"] for f in failures]
    below = [r for r in rows if r["ffr_true"] < CUTOFF]
    above = [r for r in rows if r["ffr_true"] >= CUTOFF]
    widths = [r["ffr_ci95"][1] - r["ffr_ci95"][0] for r in rows if r["ffr_ci95"]]
    parted = [r for r in rows if r.get("ffr_error_parts")]
    large = [r for r in parted if abs(r["ffr_error"]) > TARGETS["ffr_abs_err_p90"]]
    return {
        "cases": len(rows) + len(failures),
        "succeeded": len(rows),
        "failed": len(failures),
        "ffr_abs_err_median": median(err),
        "ffr_abs_err_p90": percentile(err, 90),
        "ffr_abs_err_max": percentile(err, 100),
        "ffr_error_median": median(r["ffr_error"] for r in rows),
        "ffr_ci95_coverage": float(np.mean(covered)) if covered else float("nan"),
        "ffr_ci95_width_median": median(widths),
        "ffr_decision_agreement": float(np.mean([r["decision_agrees"] for r in rows]))
        if rows else float("nan"),
        "true_below_cutoff_fraction": float(np.mean(np.asarray(truths) < CUTOFF))
        if truths else float("nan"),
        "ffr_abs_err_median_true_below": median(abs(r["ffr_error"]) for r in below),
        "ffr_abs_err_median_true_above": median(abs(r["ffr_error"]) for r in above),
        "abs_mld_error_mm": median(abs(r["mld_error_mm"]) for r in rows),
        "ffr_error_parts_abs_median": {p: median(abs(r["ffr_error_parts"][p]) for r in parted)
                                       for p in PARTS},
        "ffr_error_largest_part": {p: sum(max(PARTS, key=lambda q: abs(r["ffr_error_parts"][q]))
                                          == p for r in large) for p in PARTS},
        "ffr_error_above_p90_target": len(large),
    }


def run(cases: int | None = None, seed: int = 0, varied_per_chain: int | None = None
        ) -> dict:
    """The analytic checks, then ``cases`` regular-suite cases and ``varied_per_chain``
    cases per imaging chain (``cases`` when given, else :data:`VARIED_PER_CHAIN`), all at
    ``seed`` (module docstring)."""
    from recon.synth.suites import varied_cases

    t0 = time.perf_counter()
    checks = analytic()
    n_regular = CASES if cases is None else cases
    per_chain = varied_per_chain or (VARIED_PER_CHAIN if cases is None else cases)
    jobs = [("regular", (PRESET_CYCLE[k % len(PRESET_CYCLE)], seed + k),
             case_stenosis_pct(seed, k)) for k in range(n_regular)]
    specs = varied_cases(per_chain, seed)
    jobs += [("varied", spec, case_stenosis_pct(seed, n_regular + i))
             for i, spec in enumerate(specs)]
    outs = parallel_map(_case_job, jobs)
    rows = [o["row"] for o in outs if o["row"] is not None]
    failures = [o["failure"] for o in outs if o["failure"] is not None]

    def group(key: str) -> dict[str, dict]:
        names = dict.fromkeys(r[key] for r in [*rows, *failures])
        return {n: figures([r for r in rows if r[key] == n],
                           [f for f in failures if f[key] == n]) for n in names}

    return {
        "seed": int(seed),
        "cases_regular": n_regular,
        "cases_per_chain": per_chain,
        "stenosis_pct_range": list(STENOSIS_PCT_RANGE),
        "cutoff": CUTOFF,
        "model": FFRModel().to_dict(),
        "analytic": checks,
        "overall": figures(rows, failures),
        "suites": group("suite"),
        "chains": group("chain"),
        "anatomy": group("anatomy"),
        "targets": {k: list(v) if isinstance(v, tuple) else v for k, v in TARGETS.items()},
        "rows": rows,
        "failures": failures,
        "wall_s": time.perf_counter() - t0,
    }


def format_table(result: dict) -> str:
    """Plain-text summary of a :func:`run` result."""
    an = result["analytic"]
    tube, nar = an["straight_tube"], an["narrowing"]
    lines = [
        "FFR model (recon.lumen.ffr; a model estimate for research, not validated against "
        "a pressure wire)",
        f"straight tube r {tube['radius_mm']:g} mm x {tube['length_mm']:g} mm: drop "
        f"{tube['drop_mmhg']:.4f} mmHg, Poiseuille {tube['poiseuille_drop_mmhg']:.4f} "
        f"(rel err {tube['rel_err']:.2e}; flow rel err {tube['flow_rel_err']:.2e}) "
        f"{'PASS' if tube['pass'] else 'FAIL'} (<= {an['tolerances']['straight_tube']:.1%})",
    ]
    for r in nar["cases"]:
        lines.append(f"narrowing {r['stenosis_pct']:.0f} % x {nar['length_mm']:g} mm: drop "
                     f"{r['drop_mmhg']:.3f} mmHg, closed form {r['closed_form_drop_mmhg']:.3f} "
                     f"(FFR {r['ffr']:.4f} / {r['closed_form_ffr']:.4f}, rel err "
                     f"{r['rel_err']:.2e})")
    lines.append(f"narrowing max rel err {nar['max_rel_err']:.2e} "
                 f"{'PASS' if nar['pass'] else 'FAIL'} (<= {an['tolerances']['narrowing']:.0%})")
    lines += ["", f"reconstruction against the true lumen, seed {result['seed']} "
              f"({result['cases_regular']} regular cases, {result['cases_per_chain']} per "
              f"varied chain; stenosis {result['stenosis_pct_range'][0]:g}-"
              f"{result['stenosis_pct_range'][1]:g} % DS)"]
    head = (f"{'':<22}{'cases':>6}{'fail':>5}{'|err| med':>10}{'p90':>7}{'cover':>7}"
            f"{'agree':>7}{'<0.80':>7}{'ci w':>7}{'|MLD|':>7}")
    lines += [head, "-" * len(head)]

    def line(name: str, f: dict) -> str:
        return (f"{name:<22}{f['cases']:>6}{f['failed']:>5}{f['ffr_abs_err_median']:>10.3f}"
                f"{f['ffr_abs_err_p90']:>7.3f}{f['ffr_ci95_coverage']:>7.2f}"
                f"{f['ffr_decision_agreement']:>7.2f}{f['true_below_cutoff_fraction']:>7.2f}"
                f"{f['ffr_ci95_width_median']:>7.3f}{f['abs_mld_error_mm']:>7.3f}")

    lines += [line(n, f) for n, f in result["suites"].items()]
    lines += ["-" * len(head), line("overall", result["overall"])]
    ov = result["overall"]
    if ov.get("ffr_error_parts_abs_median"):
        med, big = ov["ffr_error_parts_abs_median"], ov["ffr_error_largest_part"]
        lines.append("error parts, median |part|: " + ", ".join(
            f"{p} {med[p]:.4f}" for p in PARTS) + f"; largest part of the "
            f"{ov['ffr_error_above_p90_target']} cases above {TARGETS['ffr_abs_err_p90']}: "
            + ", ".join(f"{p} {big[p]}" for p in PARTS))
    lines += ["", "by chain"]
    lines += [line(n, f) for n, f in result["chains"].items()]
    lines += ["", "by anatomy"]
    lines += [line(n, f) for n, f in result["anatomy"].items()]
    t = result["targets"]
    lines += ["", f"targets: |err| median <= {t['ffr_abs_err_median']}, p90 <= "
              f"{t['ffr_abs_err_p90']}, coverage {t['ffr_ci95_coverage'][0]:.0%}-"
              f"{t['ffr_ci95_coverage'][1]:.0%}, decision agreement >= "
              f"{t['ffr_decision_agreement']:.0%}, true FFR < {result['cutoff']} in >= 1/3",
              f"{result['wall_s']:.0f} s wall"]
    for f in result["failures"]:
        lines.append(f"FAILED {f['chain']} {f['preset']}/{f['seed']} {f['anatomy']}: "
                     f"{f['error']}")
    return "\n".join(lines)
