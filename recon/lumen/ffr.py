"""Angiography-derived fractional flow reserve (FFR) along the 3D lumen.

A model estimate for research: it has not been validated against a pressure wire here.
docs/ffr.md has the model with its references, the constants and the benchmark.

The model, per vessel of arc length s (mm) and lumen area A(s):

- Pressure loss dP(Q) = a Q + b Q^2 at flow Q:
  viscous (Poiseuille with the local area) a = integral of 8 pi mu / A(s)^2 ds, and a
  separation loss at each narrowing j, (Kt / 2) rho (A0_j / Amin_j - 1)^2 (Q / A0_j)^2
  (Young and Tsai 1973; Gould 1978), Kt = 1.52. A narrowing is a stretch where the lumen
  is smaller than its healthy reference area (pi / 4 times the squared reference diameter
  of the QCA, :mod:`recon.lumen.measure`); Amin_j is its least area, A0_j the reference
  area there. Along the pullback the narrowing's loss is spread linearly over the
  arc length from its throat to its distal end (where the flow separates and expands).
- Hyperemic flow driven by the mean aortic pressure Pa through the vessel into a distal
  (microvascular) resistance R set so that a healthy vessel of the proximal reference area
  A_ref carries the mean velocity v (0.35 m/s; Tu et al. 2014, 2016): R = Pa / (v A_ref).
  A_ref is the mean, over the first :attr:`FFRModel.reference_length_mm`, of the lumen's
  own (smoothed) area (``FFRModel.inlet_area="lumen"``, the default, as issue 47 defines
  it) or of the QCA's fitted healthy reference area (``"reference"``: a wrong first
  millimetre of the lumen does not move R; measured in docs/ffr.md, not better overall).
  The flow solves Pa - dP(Q) = R Q; FFR(s) = P(s) / Pa, the venous pressure taken as 0.
- A tree: each segment a vessel leaving its parent at ``join_s_mm`` of the parent's arc
  length. The healthy flow splits at each bifurcation by the reference diameters to the
  power k (7/3, Huo and Kassab 2012; 3, Murray 1926): each outlet's resistance is Pa over
  its share of the healthy inflow v A_ref. The flows then solve the network (a narrowed
  branch takes less). A branch's pullback starts at its parent's pressure at the join.

The flows are solved by SimVascular's 0D solver (svZeroDSolver, the ``svzerod`` package):
each vessel piece between joins a ``BloodVessel`` block (R_poiseuille = a, stenosis
coefficient = b), ``NORMAL_JUNCTION`` blocks at the joins, a pressure inlet and resistance
outlets; every network of a call (the reported geometry, the flow band, the posterior
draws) in one solver run. The pullback inside a piece is the same integral at the solved
flow. Units inside: mmHg, mL/s, mm.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from recon.errors import CoronaryError

FloatArray = NDArray[np.float64]

__all__ = [
    "FFRError",
    "FFRModel",
    "FFRResult",
    "FFRVessel",
    "Lumen",
    "distal_ffr",
    "vessel_coefficients",
    "loss_coefficients",
    "solve_networks",
    "tree_ffr",
    "vessel_ffr",
    "MMHG_PA",
    "RESEARCH_NOTE",
    "PRESSURE_RANGE_MMHG",
    "VELOCITY_RANGE_M_S",
    "SPLIT_EXPONENT_RANGE",
    "CLOSED_AREA_MM2",
    "INLET_AREAS",
]

MMHG_PA = 133.322387415  # Pa per mmHg
CI_Z = 1.959964  # two-sided 95 % normal quantile (as recon.pose.uncertainty)
PRESSURE_RANGE_MMHG = (40.0, 200.0)  # mean aortic pressure accepted
VELOCITY_RANGE_M_S = (0.05, 1.5)  # hyperemic mean velocity accepted
SPLIT_EXPONENT_RANGE = (2.0, 3.0)  # from area-preserving (2) to Murray (3)
#: A lumen this small (mm^2; a diameter of 0.11 mm, below any angiogram's resolution) is
#: closed: no flow can be modelled through it.
CLOSED_AREA_MM2 = 0.01
#: The shortest segment (mm) beyond the proximal reference stretch.
MIN_LENGTH_BEYOND_REFERENCE_MM = 2.0
#: What A_ref averages over the proximal stretch (FFRModel.inlet_area): the lumen's own
#: (smoothed) area, or the QCA's fitted healthy reference area.
INLET_AREAS = ("lumen", "reference")
RESEARCH_NOTE = ("a model estimate for research (angiography-derived, pressure-driven 1D "
                 "model); not validated against a pressure wire here")


class FFRError(CoronaryError):
    """The FFR cannot be modelled for this input (one line: what and where)."""


def _in_range(name: str, value: float, low: float, high: float, unit: str) -> None:
    if not (np.isfinite(value) and low <= value <= high):
        raise FFRError(f"FFR: {name} {value:g} {unit} is outside the physical range "
                       f"{low:g} to {high:g} {unit}")


@dataclass(frozen=True)
class FFRModel:
    """The model's constants (module docstring); each can be overridden.

    Attributes
    ----------
    aortic_pressure_mmhg : mean aortic pressure Pa driving the flow.
    velocity_m_s : hyperemic mean velocity of a healthy vessel of the proximal reference
        area, which sets the distal resistance.
    split_exponent : k of the diameter^k flow split at a bifurcation.
    viscosity_pa_s, density_kg_m3 : blood's.
    kt : the separation (expansion) loss coefficient.
    reference_length_mm : the proximal stretch whose mean area is A_ref.
    inlet_area : what A_ref averages over that stretch (:data:`INLET_AREAS`): "lumen",
        the lumen's own area (default), or "reference", the QCA's fitted healthy
        reference area.
    flow_band_m_s : the velocities of the band over the flow assumption.
    """

    aortic_pressure_mmhg: float = 100.0
    velocity_m_s: float = 0.35
    split_exponent: float = 7.0 / 3.0
    viscosity_pa_s: float = 3.5e-3
    density_kg_m3: float = 1060.0
    kt: float = 1.52
    reference_length_mm: float = 3.0
    flow_band_m_s: tuple[float, float] = (0.25, 0.45)
    inlet_area: str = "lumen"

    def __post_init__(self) -> None:
        _in_range("aortic pressure", self.aortic_pressure_mmhg, *PRESSURE_RANGE_MMHG, "mmHg")
        _in_range("velocity", self.velocity_m_s, *VELOCITY_RANGE_M_S, "m/s")
        for v in self.flow_band_m_s:
            _in_range("flow band velocity", v, *VELOCITY_RANGE_M_S, "m/s")
        _in_range("split exponent", self.split_exponent, *SPLIT_EXPONENT_RANGE, "")
        _in_range("viscosity", self.viscosity_pa_s, 1e-3, 2e-2, "Pa s")
        _in_range("density", self.density_kg_m3, 900.0, 1200.0, "kg/m^3")
        _in_range("Kt", self.kt, 0.0, 5.0, "")
        _in_range("reference length", self.reference_length_mm, 0.5, 20.0, "mm")
        if self.inlet_area not in INLET_AREAS:
            raise FFRError(f"FFR: inlet area {self.inlet_area!r} is not one of "
                           f"{', '.join(INLET_AREAS)}")

    def at_velocity(self, velocity_m_s: float) -> FFRModel:
        """The same model at another velocity."""
        return replace(self, velocity_m_s=float(velocity_m_s))

    def to_dict(self) -> dict:
        """JSON-ready constants, with the venous pressure (0) and the model's name."""
        out = asdict(self)
        out["flow_band_m_s"] = list(self.flow_band_m_s)
        out["venous_pressure_mmhg"] = 0.0
        out["name"] = ("pressure-driven 1D: Poiseuille + Young-Tsai separation loss, distal "
                       "resistance from the healthy velocity; flows by svZeroDSolver")
        return out


@dataclass(frozen=True, eq=False)
class Lumen:
    """One vessel's lumen as the model sees it.

    Attributes
    ----------
    s_mm : (M,) increasing arc length.
    area_mm2 : (M,) lumen area.
    reference_area_mm2 : (M,) healthy reference area (a narrowing is below it).
    """

    s_mm: FloatArray
    area_mm2: FloatArray
    reference_area_mm2: FloatArray

    @classmethod
    def from_profile(cls, profile) -> Lumen:
        """From a :class:`recon.lumen.measure.LumenProfile`: its smoothed area and the area
        of its interpolated reference diameter."""
        ref = np.pi / 4.0 * np.asarray(profile.reference_diameter_mm, dtype=float) ** 2
        return cls(np.asarray(profile.s_mm, dtype=float),
                   np.asarray(profile.area_smooth_mm2, dtype=float), ref)

    def reference_diameter_at(self, s_mm: float) -> float:
        """The reference diameter (mm) at arc length ``s_mm`` (held beyond the ends)."""
        return float(np.sqrt(4.0 / np.pi * np.interp(s_mm, self.s_mm, self.reference_area_mm2)))

    def inlet_area_mm2(self, length_mm: float, source: str = "lumen") -> float:
        """A_ref: the mean over the first ``length_mm`` (at least the first point) of the
        lumen's area (``source="lumen"``) or of the reference area (``"reference"``)."""
        near = self.s_mm <= self.s_mm[0] + length_mm
        values = self.reference_area_mm2 if source == "reference" else self.area_mm2
        return float(np.mean(values[near]))


def _cumtrapz(f: FloatArray, s: FloatArray) -> FloatArray:
    """Cumulative trapezoid integral (M,) of f over s, 0 at the first point."""
    return np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(s))])


def _runs(idx_first: NDArray[np.int64], idx_last: NDArray[np.int64]) -> tuple[
        NDArray[np.int64], NDArray[np.int64]]:
    """The indices of every run [first_j, last_j] laid end to end, and where each run
    starts in that list."""
    lengths = idx_last - idx_first + 1
    offsets = np.cumsum(lengths) - lengths
    idx = np.arange(int(lengths.sum())) - np.repeat(offsets, lengths) + np.repeat(idx_first,
                                                                                   lengths)
    return idx, offsets


def _narrowings(area: FloatArray, reference: FloatArray
                ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """(first, throat, last) index arrays (J,) of the maximal runs where area < reference
    (the throat: the run's least area, its first point when tied)."""
    below = (area < reference).astype(np.int8)
    edges = np.diff(np.concatenate([[0], below, [0]]))
    first, last = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    if first.size == 0:
        return first, first, first
    idx, offsets = _runs(first, last)
    least = np.minimum.reduceat(area[idx], offsets)
    lengths = last - first + 1
    at_least = np.where(area[idx] == np.repeat(least, lengths), idx, len(area))
    return first, np.minimum.reduceat(at_least, offsets), last


def loss_coefficients(lumen: Lumen, model: FFRModel) -> tuple[FloatArray, FloatArray]:
    """Cumulative loss coefficients along the lumen: (a (M,) mmHg s / mL, b (M,)
    mmHg s^2 / mL^2), so that the pressure lost from the first point to point i at flow
    Q (mL/s) is a[i] Q + b[i] Q^2 (module docstring)."""
    s = lumen.s_mm
    area_m2 = np.maximum(lumen.area_mm2, 1e-9) * 1e-6
    per_m = 8.0 * np.pi * model.viscosity_pa_s / area_m2**2  # Pa s / m^3 per m
    a = _cumtrapz(per_m, s * 1e-3) * 1e-6 / MMHG_PA  # Pa s / m^3 -> mmHg s / mL
    _, throat, last = _narrowings(lumen.area_mm2, lumen.reference_area_mm2)
    b = np.zeros_like(a)
    if throat.size == 0:
        return a, b
    a0 = lumen.reference_area_mm2[throat] * 1e-6
    coeff = 0.5 * model.kt * model.density_kg_m3 * (a0 / area_m2[throat] - 1.0) ** 2 / a0**2
    coeff *= 1e-12 / MMHG_PA  # Pa / (m^3/s)^2 -> mmHg / (mL/s)^2
    # each narrowing's loss: complete past its last point, a linear ramp from its throat
    done = np.zeros(len(s) + 1)
    np.add.at(done, last + 1, coeff)
    b += np.cumsum(done)[:-1]
    idx, _ = _runs(throat, last)
    n = last - throat + 1
    s0, s1 = np.repeat(s[throat], n), np.repeat(s[last], n)
    frac = np.where(s1 > s0, (s[idx] - s0) / np.where(s1 > s0, s1 - s0, 1.0), 1.0)
    b[idx] += np.repeat(coeff, n) * frac
    return a, b


@dataclass(frozen=True, eq=False)
class FFRVessel:
    """One vessel of a network: its lumen, where it leaves its parent, and the
    posterior draws of its lumen (for the interval).

    ``parent`` is the index of the parent vessel (None: the root, fed at Pa); parents
    come before their children. ``join_s_mm`` is the parent's arc length where this
    vessel leaves it.
    """

    lumen: Lumen
    parent: int | None = None
    join_s_mm: float = 0.0
    draws: tuple[Lumen, ...] = ()
    name: str = "segment"


@dataclass(frozen=True, eq=False)
class _Pieces:
    """A vessel cut at its children's joins: boundaries (P + 1,) mm, a and b (M,)."""

    cuts_mm: FloatArray
    a: FloatArray
    b: FloatArray


def solve_networks(networks: Sequence[Sequence[FFRVessel]], models: Sequence[FFRModel]
                   ) -> list[list[tuple[FloatArray, float]]]:
    """Pressure pullbacks of several networks in one svZeroDSolver run.

    ``networks[n]`` lists the vessels (each with ``lumen``, ``parent``, ``join_s_mm``);
    ``models[n]`` its model. Returns, per network and vessel, (pressure (M,) mmHg at
    the lumen's points, the flow (mL/s) into the vessel).
    """
    import svzerod

    config: dict = {
        "simulation_parameters": {"number_of_cardiac_cycles": 1,
                                  "number_of_time_pts_per_cardiac_cycle": 2,
                                  "steady_initial": True, "absolute_tolerance": 1e-10,
                                  "maximum_nonlinear_iterations": 50},
        "boundary_conditions": [], "vessels": [], "junctions": [],
    }
    layouts = [_add_network(config, n, vessels, model)
               for n, (vessels, model) in enumerate(zip(networks, models, strict=True))]
    solver = svzerod.Solver(config)
    solver.run()

    def last(name: str) -> float:
        return float(np.ravel(solver.get_single_result(name))[-1])

    out = []
    for vessels, layout, model in zip(networks, layouts, models, strict=True):
        rows = []
        for vessel, (pieces, names, inlets, outlet_r) in zip(vessels, layout, strict=True):
            p_in = np.array([last(f"pressure:{node}:{name}") for node, name in
                             zip(inlets, names, strict=True)])
            q = np.array([last(f"flow:{node}:{name}") for node, name in
                          zip(inlets, names, strict=True)])
            rows.append((_pullback(vessel.lumen, pieces, p_in, q, outlet_r, model), float(q[0])))
        out.append(rows)
    return out


def _pullback(lumen: Lumen, pieces: _Pieces, p_in: FloatArray, q: FloatArray,
              outlet_r: float, model: FFRModel) -> FloatArray:
    """Pressure (M,) along the lumen from each piece's inlet pressure and flow; checks the
    solved outlet against its resistance."""
    s = lumen.s_mm
    k = np.clip(np.searchsorted(pieces.cuts_mm, s, side="right") - 1, 0, len(q) - 1)
    a_lo = np.interp(pieces.cuts_mm[:-1], s, pieces.a)
    b_lo = np.interp(pieces.cuts_mm[:-1], s, pieces.b)
    pressure = p_in[k] - (pieces.a - a_lo[k]) * q[k] - (pieces.b - b_lo[k]) * q[k] ** 2
    if abs(pressure[-1] - outlet_r * q[-1]) > 1e-6 * model.aortic_pressure_mmhg:
        raise FFRError(f"FFR: the flow solver did not converge (outlet {pressure[-1]:.4f} "
                       f"against {outlet_r * q[-1]:.4f} mmHg)")
    return pressure


def _add_network(config: dict, n: int, vessels: Sequence[FFRVessel], model: FFRModel
                 ) -> list[tuple[_Pieces, list[str], list[str], float]]:
    """Add network ``n``'s blocks to the svZeroDSolver ``config``; per vessel, its pieces,
    their block names, their inlet node names and the outlet resistance (mmHg s / mL)."""
    pa = model.aortic_pressure_mmhg
    children: list[list[int]] = [[] for _ in vessels]
    for k, v in enumerate(vessels):
        if v.parent is not None:
            if not 0 <= v.parent < k:
                raise ValueError(f"vessel {k}: its parent {v.parent} must come before it")
            children[v.parent].append(k)
    cuts_at: list[dict[float, list[int]]] = []
    pieces: list[_Pieces] = []
    for k, v in enumerate(vessels):
        s = v.lumen.s_mm
        at: dict[float, list[int]] = {}
        for c in children[k]:
            cut = float(np.clip(vessels[c].join_s_mm, s[0], s[-1]))
            at.setdefault(cut, []).append(c)
        cuts_at.append(at)
        a, b = loss_coefficients(v.lumen, model)
        pieces.append(_Pieces(np.array([s[0], *sorted(at), s[-1]]), a, b))
    # healthy flow into each vessel and the share that goes on past each cut
    healthy = np.zeros(len(vessels))
    healthy[0] = model.velocity_m_s * vessels[0].lumen.inlet_area_mm2(
        model.reference_length_mm, model.inlet_area)
    outlet_flow = np.zeros(len(vessels))
    for k, v in enumerate(vessels):
        flow = healthy[k]
        for cut in sorted(cuts_at[k]):
            d_on = v.lumen.reference_diameter_at(cut) ** model.split_exponent
            d_off = {c: vessels[c].lumen.reference_diameter_at(vessels[c].lumen.s_mm[0])
                     ** model.split_exponent for c in cuts_at[k][cut]}
            total = d_on + sum(d_off.values())
            for c, d in d_off.items():
                healthy[c] = flow * d / total
            flow *= d_on / total
        outlet_flow[k] = flow
    # block ids run on over every network of the config (svZeroDSolver's vessel_id)
    next_id = len(config["vessels"])
    names_of: list[list[str]] = []
    ids: dict[str, int] = {}
    for p in pieces:
        names_of.append([])
        for _ in range(len(p.cuts_mm) - 1):
            names_of[-1].append(f"branch{next_id}_seg0")
            ids[names_of[-1][-1]] = next_id
            next_id += 1
    layout = []
    inlet_bc = f"IN{n}"
    config["boundary_conditions"].append({"bc_name": inlet_bc, "bc_type": "PRESSURE",
                                          "bc_values": {"P": [pa, pa], "t": [0.0, 1.0]}})
    inlet_of: dict[str, str] = {names_of[0][0]: inlet_bc}
    for k, v in enumerate(vessels):
        p = pieces[k]
        names = names_of[k]
        outlet_r = pa / max(outlet_flow[k], 1e-12)
        out_bc = f"OUT{n}_{k}"
        config["boundary_conditions"].append({"bc_name": out_bc, "bc_type": "RESISTANCE",
                                              "bc_values": {"R": outlet_r, "Pd": 0.0}})
        a_at = np.interp(p.cuts_mm, v.lumen.s_mm, p.a)
        b_at = np.interp(p.cuts_mm, v.lumen.s_mm, p.b)
        for j, name in enumerate(names):
            bcs = {}
            if name in inlet_of and inlet_of[name] == inlet_bc:
                bcs["inlet"] = inlet_bc
            if j == len(names) - 1:
                bcs["outlet"] = out_bc
            block = {"vessel_id": ids[name], "vessel_name": name,
                     "vessel_length": max(float(p.cuts_mm[j + 1] - p.cuts_mm[j]), 1e-3),
                     "zero_d_element_type": "BloodVessel",
                     "zero_d_element_values": {"R_poiseuille": float(a_at[j + 1] - a_at[j]),
                                               "C": 0.0, "L": 0.0,
                                               "stenosis_coefficient":
                                                   float(b_at[j + 1] - b_at[j])}}
            if bcs:
                block["boundary_conditions"] = bcs
            config["vessels"].append(block)
        for j, cut in enumerate(sorted(cuts_at[k])):
            junction = f"J{n}_{k}_{j}"
            outs = [names[j + 1]] + [names_of[c][0] for c in cuts_at[k][cut]]
            config["junctions"].append({"junction_name": junction,
                                        "junction_type": "NORMAL_JUNCTION",
                                        "inlet_vessels": [ids[names[j]]],
                                        "outlet_vessels": [ids[o] for o in outs]})
            for o in outs:
                inlet_of[o] = junction
        layout.append((p, names, [inlet_of[name] for name in names], outlet_r))
    return layout


@dataclass(frozen=True, eq=False)
class FFRResult:
    """One vessel's FFR: the pullback, its 95 % interval and the band over the flow.

    Attributes
    ----------
    s_mm : (M,) arc length of the pullback (the vessel's profile).
    ffr : (M,) P(s) / Pa, proximal to distal.
    model : the model behind it.
    flow_ml_s : the modelled hyperemic flow into the vessel.
    ffr_lo, ffr_hi : (M,) 95 % interval along the pullback from the geometry posterior's
        draws (value +- 1.96 sd of the draws, clipped to [0, 1]); None without draws.
    n_draws : the draws behind the interval.
    band : (2, M) pullbacks at the two velocities of ``model.flow_band_m_s``: the band
        over the flow assumption (not a confidence interval).
    """

    s_mm: FloatArray
    ffr: FloatArray
    model: FFRModel
    flow_ml_s: float
    ffr_lo: FloatArray | None = None
    ffr_hi: FloatArray | None = None
    n_draws: int = 0
    band: FloatArray = field(default_factory=lambda: np.zeros((2, 0)))

    @property
    def distal(self) -> float:
        """FFR at the vessel's distal end."""
        return float(self.ffr[-1])

    @property
    def ci95(self) -> tuple[float, float] | None:
        """The distal FFR's 95 % interval (None without draws)."""
        if self.ffr_lo is None or self.ffr_hi is None:
            return None
        return float(self.ffr_lo[-1]), float(self.ffr_hi[-1])

    @property
    def flow_band(self) -> tuple[float, float]:
        """The distal FFR at the band's two velocities, low to high FFR."""
        ends = sorted(float(x) for x in self.band[:, -1])
        return ends[0], ends[1]

    def to_dict(self) -> dict:
        """The report's ``ffr`` block: the pullback (``s_mm``, ``ffr``, its 95 % interval
        ``ci95_lo`` / ``ci95_hi``), ``distal`` and ``ci95``, ``flow_band``, ``model``."""
        def r4(x: FloatArray | None) -> list[float] | None:
            return None if x is None else [round(float(v), 4) for v in x]

        ci = self.ci95
        return {
            "distal": round(self.distal, 4),
            "ci95": None if ci is None else [round(ci[0], 4), round(ci[1], 4)],
            "s_mm": [round(float(v), 3) for v in self.s_mm],
            "ffr": r4(self.ffr),
            "ci95_lo": r4(self.ffr_lo),
            "ci95_hi": r4(self.ffr_hi),
            "interval": (f"95 % interval from {self.n_draws} draws of the geometry posterior "
                         "(the measurement intervals' draws, recon.pose.uncertainty): FFR +- "
                         "1.96 sd" if self.n_draws else None),
            "flow_band": {
                "label": "band over the flow assumption (hyperemic velocity "
                         f"{self.model.flow_band_m_s[0]:g}-{self.model.flow_band_m_s[1]:g} "
                         "m/s), not a confidence interval",
                "velocity_m_s": list(self.model.flow_band_m_s),
                "ffr": [round(float(v), 4) for v in self.band[:, -1]],
                "ffr_pullback": [r4(row) for row in self.band],
            },
            "flow_ml_s": round(self.flow_ml_s, 4),
            "model": self.model.to_dict(),
            "research_use": RESEARCH_NOTE,
        }


def _check(vessel: FFRVessel, model: FFRModel, root: bool) -> None:
    """Refuse a lumen the model cannot take (FFRError, one line naming the segment)."""
    lumen = vessel.lumen
    s, area = lumen.s_mm, lumen.area_mm2
    if len(s) < 2 or s.shape != area.shape or s.shape != lumen.reference_area_mm2.shape:
        raise FFRError(f"FFR: segment {vessel.name!r} has {len(s)} lumen point(s); at least 2 "
                       "are needed")
    if not (np.all(np.isfinite(s)) and np.all(np.isfinite(area))
            and np.all(np.isfinite(lumen.reference_area_mm2))) or np.any(np.diff(s) <= 0):
        raise FFRError(f"FFR: segment {vessel.name!r}: its lumen profile is not finite and "
                       "increasing in arc length")
    closed = np.flatnonzero(area <= CLOSED_AREA_MM2)
    if closed.size:
        i = int(closed[0])
        raise FFRError(f"FFR: segment {vessel.name!r}: the lumen closes at {s[i]:.1f} mm "
                       f"(area {max(area[i], 0.0):.3f} mm^2, at most {CLOSED_AREA_MM2} is "
                       "taken as closed): no flow can be modelled through it")
    shortest = model.reference_length_mm + MIN_LENGTH_BEYOND_REFERENCE_MM
    if root and s[-1] - s[0] < shortest:
        raise FFRError(f"FFR: segment {vessel.name!r} is {s[-1] - s[0]:.1f} mm long; at least "
                       f"{shortest:g} mm is needed (its first {model.reference_length_mm:g} mm "
                       "set the reference area)")


def _on_points(pressure: FloatArray, lumen: Lumen, m: int) -> FloatArray:
    """A draw's pullback (its own M' points) at the reported lumen's m points, by the
    same arc-length fraction."""
    if len(pressure) == m:
        return pressure
    f = (lumen.s_mm - lumen.s_mm[0]) / max(float(lumen.s_mm[-1] - lumen.s_mm[0]), 1e-12)
    return np.interp(np.linspace(0.0, 1.0, m), f, pressure)


def tree_ffr(vessels: Sequence[FFRVessel], model: FFRModel | None = None) -> list[FFRResult]:
    """Every vessel's FFR over the network (module docstring), with the interval from the
    vessels' draws (draw k of every vessel makes network k; as many as the vessel with
    the fewest has) and the band over the flow. Raises FFRError on a lumen the model
    cannot take."""
    model = model or FFRModel()
    for k, v in enumerate(vessels):
        _check(v, model, root=k == 0)
    n_draws = min((len(v.draws) for v in vessels), default=0)
    nominal = list(vessels)
    networks = [nominal] * 3 + [[replace(v, lumen=v.draws[k]) for v in vessels]
                                for k in range(n_draws)]
    models = [model, *(model.at_velocity(u) for u in model.flow_band_m_s)] + [model] * n_draws
    solved = solve_networks(networks, models)
    pa = model.aortic_pressure_mmhg
    out = []
    for i, v in enumerate(vessels):
        m = len(v.lumen.s_mm)
        ffr = solved[0][i][0] / pa
        band = np.stack([solved[1][i][0], solved[2][i][0]]) / pa
        lo = hi = None
        if n_draws >= 2:
            draws = np.stack([_on_points(solved[3 + k][i][0], v.draws[k], m)
                              for k in range(n_draws)]) / pa
            sd = np.std(draws, axis=0, ddof=1)
            lo = np.clip(ffr - CI_Z * sd, 0.0, 1.0)
            hi = np.clip(ffr + CI_Z * sd, 0.0, 1.0)
        out.append(FFRResult(s_mm=v.lumen.s_mm, ffr=ffr, model=model,
                             flow_ml_s=solved[0][i][1], ffr_lo=lo, ffr_hi=hi,
                             n_draws=n_draws if lo is not None else 0, band=band))
    return out


def vessel_ffr(profile, draws: Sequence = (), model: FFRModel | None = None,
               name: str = "segment") -> FFRResult:
    """One segment's FFR from its :class:`recon.lumen.measure.LumenProfile` and the
    profiles of the geometry posterior's draws (``MeasurementIntervals.profiles``)."""
    vessel = FFRVessel(Lumen.from_profile(profile), draws=tuple(Lumen.from_profile(p)
                                                                for p in draws), name=name)
    return tree_ffr([vessel], model)[0]


def vessel_coefficients(lumen: Lumen, model: FFRModel | None = None
                        ) -> tuple[float, float, float]:
    """One vessel's three numbers (no tree): the distal resistance R = Pa / (v A_ref)
    (mmHg s / mL, A_ref as ``model.inlet_area`` says), the viscous coefficient a
    (mmHg s / mL) and the separation coefficient b (mmHg s^2 / mL^2) of the whole vessel,
    so that Pa = (R + a) Q + b Q^2 (module docstring)."""
    model = model or FFRModel()
    a, b = loss_coefficients(lumen, model)
    area_ref = lumen.inlet_area_mm2(model.reference_length_mm, model.inlet_area)
    return model.aortic_pressure_mmhg / (model.velocity_m_s * area_ref), float(a[-1]), \
        float(b[-1])


def distal_ffr(resistance: float, a: float, b: float, aortic_pressure_mmhg: float) -> float:
    """The closed form of one vessel's distal FFR: Q the positive root of
    b Q^2 + (R + a) Q - Pa = 0, FFR = R Q / Pa (what svZeroDSolver solves for one vessel)."""
    pa = aortic_pressure_mmhg
    q = 2.0 * pa / ((a + resistance) + np.sqrt((a + resistance) ** 2 + 4.0 * b * pa))
    return float(resistance * q / pa)
