"""Every lesion of a segment, with 95 % intervals, and which one is "the" lesion.

:func:`recon.lumen.measure.narrowings` finds every narrowing of a lumen profile and
says which are supported; :func:`recon.lumen.measure.lesions_of` keeps those of at
least the 25 % floor and merges tandems (narrowings less than 3 reference diameters
apart are one lesion, as the SYNTAX score counts them). Here:

- :func:`lesion_report` numbers the lesions proximal to distal (lesion 1, 2, ...)
  and gives each its 95 % intervals from the geometry posterior's draws
  (:func:`recon.pose.uncertainty.measurement_intervals` keeps each draw's profile).
  In every draw the stretch of the reported lesion (same centerline points) is
  measured again: its least diameter, the reference there, % stenoses, MLA and the
  MLD's site; its length is that of the draw's lesion that overlaps the stretch
  most (0 when the draw finds none there, counted in ``found_fraction``). An
  interval is the reported value +- 1.96 sd of the draws (centred on the reported
  figure, as the segment's intervals are), lengths and diameters clipped at 0.
  A lesion made of a tandem lists its narrowings (``parts``); a lesion whose % diameter
  stenosis interval reaches below the floor is marked ``borderline``.
- Borderline narrowings (``LesionReport.borderline``): supported narrowings below the
  floor whose % diameter stenosis 95 % interval reaches it, outside every lesion,
  listed with their intervals next to the lesions (report.json
  ``lesion_assessment.borderline``), so that a narrowing near the floor, which click
  noise lifts above it in one run and not in another, is shown in every run rather
  than appearing and vanishing as a lesion without a word (issue 46). They are not
  lesions: no primary is chosen among them.
- The primary lesion (the segment's ``measurements``) is the most severe by %
  diameter stenosis. It is unambiguous only when its % diameter stenosis lies above
  every other lesion's 95 % interval; otherwise ``primary_ambiguous`` is True and
  the lesions whose interval reaches it are named. Without intervals (no posterior)
  two or more lesions are ambiguous: nothing tells them apart.
- :func:`ostium_zone_end_s_mm`: how far past a branch's carina its parent's lumen
  stays within the reach of the 2D radius fits in every view (the half-width of
  the branch's profile window, :mod:`recon.trace.profile_fit`): a fit
  whose window holds the parent's edge reads the branch too narrow there (on the
  demo's healthy side branch, 30 % too narrow 1 mm past the carina). Where one view
  is clear the sections take that view's radius (the tree's overlap marking), so the
  zone ends there: a true ostial lesion seen in the clear view is measured. A narrowing
  there is a lesion only when the profile past the zone supports it
  (:mod:`recon.lumen.measure`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from recon.geometry import ViewGeometry
from recon.lumen.measure import (
    MIN_LESION_DS_PCT,
    LumenProfile,
    Narrowing,
    lesions_of,
    narrowings,
    tandem_groups,
)

FloatArray = NDArray[np.float64]

__all__ = [
    "Lesion",
    "LesionReport",
    "lesion_report",
    "lesion_sets_equal",
    "lesions_kept_or_borderline",
    "ostium_zone_end_s_mm",
    "LESION_CI_KEYS",
]

CI_Z = 1.959964  # two-sided 95 % normal quantile
#: The figures of a lesion that get a 95 % interval.
LESION_CI_KEYS = ("mld_mm", "mld_s_mm", "diameter_stenosis_pct", "area_stenosis_pct",
                  "length_mm", "mla_mm2", "reference_diameter_mm")
#: A zone longer than this fraction of the branch past its carina is cut there.
OSTIUM_ZONE_MAX_FRACTION = 0.5
#: The branch must stay clear of its parent over this much arc (mm) for the zone to end.
OSTIUM_CLEAR_RUN_MM = 1.0


@dataclass(frozen=True)
class Lesion:
    """A numbered lesion: its figures (:class:`~recon.lumen.measure.Narrowing`), their
    95 % intervals (``{key: (lo, hi)}``, empty without a posterior) and the share of
    the posterior draws that found a lesion on its stretch (None without draws)."""

    number: int
    narrowing: Narrowing
    ci95: dict = field(default_factory=dict)
    found_fraction: float | None = None
    parts: tuple[Narrowing, ...] = ()  # a tandem's narrowings (module docstring), else ()

    @property
    def borderline(self) -> bool:
        """True when its % diameter stenosis 95 % interval reaches below the lesion floor
        (False without intervals)."""
        ci = self.ci95.get("diameter_stenosis_pct")
        return ci is not None and ci[0] < MIN_LESION_DS_PCT

    def to_dict(self) -> dict:
        """JSON-ready: number, site, the figures, ``ci95``, ``borderline`` and a tandem's
        ``parts`` (each narrowing's MLD site, % DS and extent)."""
        n = self.narrowing
        return {
            "number": self.number,
            "site": _site(n),
            "mld_mm": n.mld_mm,
            "mld_s_mm": n.mld_s_mm,
            "reference_diameter_mm": n.reference_diameter_mm,
            "diameter_stenosis_pct": n.diameter_stenosis_pct,
            "area_stenosis_pct": n.area_stenosis_pct,
            "mla_mm2": n.mla_mm2,
            "start_s_mm": n.start_s_mm,
            "end_s_mm": n.end_s_mm,
            "length_mm": n.length_mm,
            "zone": n.zone or None,
            "ci95": {k: [float(lo), float(hi)] for k, (lo, hi) in self.ci95.items()} or None,
            "found_fraction": self.found_fraction,
            "borderline": self.borderline,
            "parts": [{"mld_s_mm": p.mld_s_mm, "diameter_stenosis_pct": p.diameter_stenosis_pct,
                       "start_s_mm": p.start_s_mm, "end_s_mm": p.end_s_mm}
                      for p in self.parts],
        }


def _unconfirmed(n: Narrowing) -> str:
    """Why a narrowing in a zone is not a lesion, in one clause."""
    why = ("the parent's lumen lies within the radius fits' reach there"
           if n.zone == "ostium" else "where a trace starts or fades")
    return (f"a {n.diameter_stenosis_pct:.0f} % narrowing at {n.mld_s_mm:.1f} mm ({n.zone}) "
            f"is not confirmed: {why}, and past it the profile is not narrowed")


def _borderline_clause(b: Lesion) -> str:
    """A borderline narrowing in one clause."""
    n = b.narrowing
    lo, hi = b.ci95["diameter_stenosis_pct"]
    return (f"a borderline {n.diameter_stenosis_pct:.0f} % narrowing ({lo:.0f} to {hi:.0f} %) at "
            f"{n.mld_s_mm:.1f} mm: below the {MIN_LESION_DS_PCT:.0f} % lesion floor, but its "
            "95 % interval reaches it")


def _site(n: Narrowing) -> str:
    """Where a narrowing is, in words: its MLD's arc length and its zone."""
    where = f"{n.mld_s_mm:.1f} mm"
    return f"{where} ({n.zone})" if n.zone else where


@dataclass(frozen=True)
class LesionReport:
    """A segment's lesions (proximal to distal), the primary one and the narrowings
    that were not lesions for want of support (:mod:`recon.lumen.measure`)."""

    lesions: tuple[Lesion, ...]
    unsupported: tuple[Narrowing, ...]
    primary: int | None  # index into lesions
    primary_ambiguous: bool
    ambiguous_with: tuple[int, ...] = ()  # lesion numbers whose interval reaches the primary
    trusted_mm: tuple[float, float] = (0.0, 0.0)
    ostium: bool = False
    borderline: tuple[Lesion, ...] = ()  # narrowings below the floor whose interval reaches it

    @property
    def primary_lesion(self) -> Lesion | None:
        return None if self.primary is None else self.lesions[self.primary]

    def summary(self) -> str:
        """One line: how many lesions, which is the primary and whether it stands out, and
        the narrowings not confirmed."""
        return "; ".join([self._lesions_line(), *(_borderline_clause(b) for b in self.borderline),
                          *(_unconfirmed(n) for n in self.unsupported)])

    def _lesions_line(self) -> str:
        if not self.lesions:
            return "no lesion"
        main = self.lesions[self.primary]
        words = f"{len(self.lesions)} lesion{'s' * (len(self.lesions) > 1)}"
        if len(self.lesions) == 1:
            return f"{words}: lesion 1 at {_site(main.narrowing)}"
        if not self.primary_ambiguous:
            return (f"{words}; lesion {main.number} ({main.narrowing.diameter_stenosis_pct:.0f} "
                    "%) is the most severe beyond the others' 95 % intervals")
        others = ", ".join(str(k) for k in self.ambiguous_with)
        return (f"{words}; no single most severe lesion: lesion {main.number} "
                f"({main.narrowing.diameter_stenosis_pct:.0f} %) lies within the 95 % "
                f"interval of lesion {others}")

    def lesion_list(self) -> list[dict]:
        """report.json's ``lesions``: every lesion's :meth:`Lesion.to_dict`."""
        return [les.to_dict() for les in self.lesions]

    def assessment(self) -> dict:
        """report.json's ``lesion_assessment``: the primary lesion's number (the one of
        ``measurements``), whether it is ambiguous and with which, a one-line summary,
        the trusted stretch and the narrowings that were not lesions for want of
        support."""
        return {
            "primary": None if self.primary is None else self.lesions[self.primary].number,
            "primary_ambiguous": self.primary_ambiguous,
            "ambiguous_with": list(self.ambiguous_with),
            "summary": self.summary(),
            "trusted_s_mm": [float(v) for v in self.trusted_mm],
            "proximal_zone": "ostium" if self.ostium else "clicked end",
            "floor_pct": MIN_LESION_DS_PCT,
            "borderline": [b.to_dict() for b in self.borderline],
            "unsupported": [{"site": _site(n), "diameter_stenosis_pct": n.diameter_stenosis_pct,
                             "mld_s_mm": n.mld_s_mm, "start_s_mm": n.start_s_mm,
                             "end_s_mm": n.end_s_mm, "zone": n.zone}
                            for n in self.unsupported],
        }


def lesion_report(profile: LumenProfile, draws: Sequence[LumenProfile] = ()) -> LesionReport:
    """The lesions of ``profile`` with intervals from the posterior draws' profiles
    (module docstring); each draw must have the profile's M points."""
    found = narrowings(profile)
    groups = tandem_groups([n for n in found if n.supported])
    draws = [d for d in draws if len(d.s_mm) == len(profile.s_mm)]
    lesions = []
    for k, (n, group) in enumerate(zip(lesions_of(profile), groups, strict=True), start=1):
        ci, frac = _intervals(profile, n, draws) if len(draws) >= 2 else ({}, None)
        lesions.append(Lesion(number=k, narrowing=n, ci95=ci, found_fraction=frac,
                              parts=group if len(group) > 1 else ()))
    primary, ambiguous, others = None, False, ()
    if lesions:
        primary = int(np.argmax([les.narrowing.diameter_stenosis_pct for les in lesions]))
        ds = lesions[primary].narrowing.diameter_stenosis_pct
        rivals = [les for k, les in enumerate(lesions) if k != primary]
        if rivals and not draws:
            others = tuple(les.number for les in rivals)
        else:
            others = tuple(les.number for les in rivals
                           if les.ci95.get("diameter_stenosis_pct", (0.0, 0.0))[1] >= ds)
        ambiguous = bool(others)
    return LesionReport(lesions=tuple(lesions), unsupported=tuple(n for n in found
                                                                   if not n.supported),
                        primary=primary, primary_ambiguous=ambiguous, ambiguous_with=others,
                        trusted_mm=profile.trusted_range_mm, ostium=profile.ostium,
                        borderline=_borderline(profile, lesions, draws))


def _borderline(profile: LumenProfile, lesions: Sequence[Lesion],
                draws: Sequence[LumenProfile]) -> tuple[Lesion, ...]:
    """The supported narrowings below the floor, outside every lesion, whose % diameter
    stenosis 95 % interval reaches the floor, numbered proximal to distal (none without
    at least two draws)."""
    if len(draws) < 2:
        return ()
    out = []
    for n in narrowings(profile, min_ds_pct=0.0):
        if not n.supported or n.diameter_stenosis_pct >= MIN_LESION_DS_PCT or any(
                les.narrowing.start_s_mm <= n.mld_s_mm <= les.narrowing.end_s_mm
                for les in lesions):
            continue
        ci, frac = _intervals(profile, n, draws)
        if ci["diameter_stenosis_pct"][1] >= MIN_LESION_DS_PCT:
            out.append(Lesion(number=len(out) + 1, narrowing=n, ci95=ci, found_fraction=frac))
    return tuple(out)


def _intervals(profile: LumenProfile, lesion: Narrowing, draws: Sequence[LumenProfile]
               ) -> tuple[dict, float]:
    """95 % intervals of one lesion's figures over the draws, and the share that found it."""
    s = profile.s_mm
    stretch = np.flatnonzero((s >= lesion.start_s_mm) & (s <= lesion.end_s_mm))
    if stretch.size == 0:
        stretch = np.array([int(np.argmin(np.abs(s - lesion.mld_s_mm)))])
    values: dict[str, list[float]] = {k: [] for k in LESION_CI_KEYS}
    hits = 0
    for d in draws:
        i = int(stretch[np.argmin(d.diameter_smooth_mm[stretch])])
        mld, ref = float(d.diameter_smooth_mm[i]), float(d.reference_diameter_mm[i])
        mla = float(np.min(d.area_smooth_mm2[stretch]))
        length = _overlapping_length(d, d.s_mm[stretch[0]], d.s_mm[stretch[-1]])
        hits += length > 0.0
        values["mld_mm"].append(mld)
        values["mld_s_mm"].append(float(d.s_mm[i]))
        values["reference_diameter_mm"].append(ref)
        values["diameter_stenosis_pct"].append(100.0 * (1.0 - mld / ref))
        values["area_stenosis_pct"].append(100.0 * (1.0 - mla / (np.pi * ref**2 / 4.0)))
        values["mla_mm2"].append(mla)
        values["length_mm"].append(length)
    nominal = {"mld_mm": lesion.mld_mm, "mld_s_mm": lesion.mld_s_mm,
               "reference_diameter_mm": lesion.reference_diameter_mm,
               "diameter_stenosis_pct": lesion.diameter_stenosis_pct,
               "area_stenosis_pct": lesion.area_stenosis_pct, "mla_mm2": lesion.mla_mm2,
               "length_mm": lesion.length_mm}
    ci = {}
    for key, v in values.items():
        sd = float(np.std(v, ddof=1))
        lo, hi = nominal[key] - CI_Z * sd, nominal[key] + CI_Z * sd
        if not key.endswith("_pct"):
            lo = max(lo, 0.0)
        if key == "mld_s_mm":  # the site stays on the measured stretch
            lo, hi = max(lo, float(s[0])), min(hi, float(s[-1]))
        ci[key] = (float(lo), float(hi))
    return ci, hits / len(draws)


def _overlapping_length(draw: LumenProfile, start: float, end: float) -> float:
    """Length (mm) of the draw's lesion that overlaps [start, end] (the draw's own arc
    lengths) most; 0 for none."""
    best, overlap = 0.0, 0.0
    for n in lesions_of(draw):
        o = min(n.end_s_mm, end) - max(n.start_s_mm, start)
        if o > overlap:
            best, overlap = n.length_mm, o
    return best


def lesion_sets_equal(a: Sequence[dict], b: Sequence[dict], rule: str = "overlap") -> bool:
    """Whether two runs found the same lesions: as many, paired proximal to distal, and
    each pair the same lesion. ``a``, ``b``: lists of :meth:`Lesion.to_dict`
    (report.json's ``lesions``; ``mld_s_mm``, ``start_s_mm``, ``end_s_mm`` are read).

    ``rule="overlap"``: a pair is one lesion when their extents (``start_s_mm`` ..
    ``end_s_mm``) overlap: they cover the same stretch of vessel, wherever along it each
    run found the least diameter. ``rule="mld"`` (the rule before issue 46's second
    pass, kept to report the old figure beside the new): each one's MLD inside the
    other's extent, which calls one long lesion two when its MLD moves between two
    minima of similar depth.
    """
    if rule not in ("overlap", "mld"):
        raise ValueError(f"rule must be 'overlap' or 'mld', got {rule!r}")
    if len(a) != len(b):
        return False
    for x, y in zip(sorted(a, key=lambda d: d["mld_s_mm"]), sorted(b, key=lambda d: d["mld_s_mm"]),
                    strict=True):
        if rule == "overlap":
            same = min(x["end_s_mm"], y["end_s_mm"]) > max(x["start_s_mm"], y["start_s_mm"])
        else:
            same = (y["start_s_mm"] <= x["mld_s_mm"] <= y["end_s_mm"]
                    and x["start_s_mm"] <= y["mld_s_mm"] <= x["end_s_mm"])
        if not same:
            return False
    return True


def lesions_kept_or_borderline(a: Sequence[dict], b: Sequence[dict],
                               borderline_a: Sequence[dict] = (),
                               borderline_b: Sequence[dict] = ()) -> bool:
    """Whether no lesion of one run is missing from the other without a word: every lesion
    of ``a`` overlaps (extents) a lesion or a borderline narrowing of ``b``, and every
    lesion of ``b`` one of ``a``. Looser than :func:`lesion_sets_equal`: a narrowing that
    is a lesion in one run and, below the floor with its interval reaching it, a borderline
    narrowing in the other counts as kept (it is shown in both, on either side of the
    floor). Dicts as :func:`lesion_sets_equal` reads them."""

    def found(x: dict, others: Sequence[dict]) -> bool:
        return any(min(x["end_s_mm"], y["end_s_mm"]) > max(x["start_s_mm"], y["start_s_mm"])
                   for y in others)

    return (all(found(x, [*b, *borderline_b]) for x in a)
            and all(found(y, [*a, *borderline_a]) for y in b))


def ostium_zone_end_s_mm(
    X_world: FloatArray, s_mm: FloatArray, radius_mm: float, parent_X_world: FloatArray,
    parent_radius_mm: FloatArray, views: Sequence[ViewGeometry], from_s_mm: float,
) -> float:
    """Arc length (mm) along a branch where its ostium zone ends (module docstring).

    Parameters
    ----------
    X_world : (M, 3) the branch's 3D centerline, s_mm (M,) its arc length.
    radius_mm : the branch's lumen radius past its ostium (its reference).
    parent_X_world : (P, 3) the parent's centerline, parent_radius_mm (P,) its radius.
    views : the views whose radius fits made the branch's sections (A and B).
    from_s_mm : the carina's arc length: the zone starts there.

    The zone runs from the carina to the first point from which, for
    :data:`OSTIUM_CLEAR_RUN_MM`, the parent's projected lumen edge lies beyond the
    reach of the branch's profile fit in at least one view; it is at most
    :data:`OSTIUM_ZONE_MAX_FRACTION` of the branch past the carina.
    """
    from recon.correspond.triangulation import radius_mm_eq11
    from recon.trace.profile_fit import half_width_for

    X = np.asarray(X_world, dtype=float)
    s = np.asarray(s_mm, dtype=float)
    P = np.asarray(parent_X_world, dtype=float)
    r_p = np.asarray(parent_radius_mm, dtype=float)
    near = np.ones(len(s), dtype=bool)
    for view in views:
        q, qp = view.project(X), view.project(P)
        mm_b = radius_mm_eq11(np.ones(len(X)), X, view)  # mm per px at each point
        mm_p = radius_mm_eq11(np.ones(len(P)), P, view)
        r_b_px = float(np.median(radius_mm / mm_b))
        reach = half_width_for(r_b_px)
        gap = np.linalg.norm(q[:, None, :] - qp[None, :, :], axis=2) - (r_p / mm_p)[None, :]
        near &= gap.min(axis=1) < reach
    start = int(np.searchsorted(s, from_s_mm))
    cap = from_s_mm + OSTIUM_ZONE_MAX_FRACTION * (s[-1] - from_s_mm)
    step = float(np.median(np.diff(s))) if len(s) > 1 else 1.0
    run = max(1, int(round(OSTIUM_CLEAR_RUN_MM / max(step, 1e-9))))
    clear = ~near[start:]
    if len(clear) >= run:
        runs = np.convolve(clear.astype(int), np.ones(run, dtype=int), "valid") == run
        hit = np.flatnonzero(runs)
        if hit.size:
            return float(min(s[start + int(hit[0])], cap))
    return float(cap)
