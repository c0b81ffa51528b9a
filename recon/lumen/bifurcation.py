"""Where a branch leaves its parent: the 3D join and bifurcation QCA.

A branch's 3D centerline starts at its bifurcation click, triangulated on
its own; :class:`Junction` moves that start onto the parent's 3D
centerline (the nearest point J) and blends the shift out along the part
of the branch that still lies inside the parent's lumen, so the branches
meet without a gap and the branch's direction beyond the carina is its own.

Bifurcation QCA (definitions, as in 3D bifurcation QCA; Girasis et al.,
EuroIntervention, for the phantom validation of such a tool):

- J is the junction point on the parent, ``r_J`` the parent's lumen radius
  there. The carina is taken where the branch's centerline leaves the
  parent's lumen: the first branch point farther than the parent's local
  radius from the parent's centerline (arc length ``carina_s_mm`` along
  the branch).
- Three segments: proximal main (parent, arc length from J - r_J back
  :data:`QCA_SEGMENT_MM`), distal main (parent, J + r_J onwards) and side
  branch (branch, carina onwards), each :data:`QCA_SEGMENT_MM` long or up
  to the vessel's end.
- Each segment's reference diameter is the mean of its vessel's
  interpolated reference (:mod:`recon.lumen.measure`) over the segment, its MLD
  the least smoothed diameter in it, its %DS = 100 (1 - MLD / reference at
  the MLD).
- Directions: the principal axis of the centerline points over
  :data:`DIRECTION_WINDOW_MM` (0 to 4 mm) beyond the segment's start (the
  carina side), pointing away from the bifurcation. The bifurcation
  (distal) angle is between the distal main and the side branch
  directions, the proximal angle between the proximal main (pointing
  proximally) and the side branch.
- Medina class: (proximal main, distal main, side branch), 1 where that
  segment's %DS >= 50, else 0.
- The origin's plausibility: a straight branch leaving its parent's lumen
  (radius r_J) at angle theta clears it after about r_J / sin(theta) of its
  own arc. A reconstructed carina more than :data:`ORIGIN_CARINA_FACTOR`
  times that far along the branch is not a branch's origin: in one view the
  trace most likely runs along the parent first (a faint or narrowed ostium
  skipped). ``origin_warning`` then says so; the angle and the side
  branch's first millimetres are uncertain.

:func:`sharpest_turn_deg` measures how sharply a centerline turns near its
start (the largest angle between successive chords of
:data:`TURN_CHORD_MM`): a join that bends a branch more than the vessel
itself turns shows there.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from recon.types import Centerline3D, arclength

FloatArray = NDArray[np.float64]

__all__ = [
    "Junction",
    "BifurcationQCA",
    "SegmentQCA",
    "nearest_on_polyline",
    "carina_s_mm",
    "direction_away",
    "bifurcation_angles_deg",
    "bifurcation_qca",
    "fill_names",
    "literal",
    "QCA_SEGMENT_MM",
    "DIRECTION_WINDOW_MM",
    "MEDINA_DS_PCT",
    "TURN_CHORD_MM",
    "sharpest_turn_deg",
    "ORIGIN_CARINA_FACTOR",
    "origin_warning",
]

QCA_SEGMENT_MM = 10.0  # length of each of the three bifurcation segments
DIRECTION_WINDOW_MM = (0.0, 4.0)  # direction fit window beyond each segment's start
MEDINA_DS_PCT = 50.0  # a Medina 1: diameter stenosis at least this
_MIN_BLEND_MM = 1.0
MAX_JOIN_TURN_DEG = 10.0  # the most the join's blend may turn a branch
TURN_CHORD_MM = 1.0  # chord length of sharpest_turn_deg
#: A carina farther along the branch than this times r_J / sin(angle) is implausible.
ORIGIN_CARINA_FACTOR = 2.0


def nearest_on_polyline(X_world: FloatArray, point: ArrayLike) -> tuple[FloatArray, float, int]:
    """The point of the polyline X_world (P, 3) nearest ``point`` (3,).

    Returns (that point (3,), its arc length along the polyline (mm), the
    index of the polyline vertex before it).
    """
    X = np.asarray(X_world, dtype=float)
    p = np.asarray(point, dtype=float)
    seg = np.diff(X, axis=0)
    len2 = np.maximum(np.einsum("ij,ij->i", seg, seg), 1e-18)
    tau = np.clip(np.einsum("ij,ij->i", p - X[:-1], seg) / len2, 0.0, 1.0)
    foot = X[:-1] + tau[:, None] * seg
    k = int(np.argmin(np.sum((foot - p) ** 2, axis=1)))
    s = arclength(X)
    return foot[k], float(s[k] + tau[k] * np.sqrt(len2[k])), k


def _distance_to_polyline(points: FloatArray, X_world: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Distance (N,) of points (N, 3) to the polyline (P, 3), and the feet's arc length (N,)."""
    s = arclength(X_world)
    seg = np.diff(X_world, axis=0)  # (P-1, 3)
    len2 = np.maximum(np.einsum("ij,ij->i", seg, seg), 1e-18)
    rel = points[:, None, :] - X_world[None, :-1, :]  # (N, P-1, 3)
    tau = np.clip(np.einsum("npk,pk->np", rel, seg) / len2, 0.0, 1.0)
    d2 = np.sum((rel - tau[..., None] * seg[None]) ** 2, axis=2)
    k = np.argmin(d2, axis=1)
    n = np.arange(len(points))
    return np.sqrt(d2[n, k]), s[k] + tau[n, k] * np.sqrt(len2[k])


def carina_s_mm(branch_X: FloatArray, parent_X: FloatArray, parent_radius_mm: FloatArray) -> float:
    """Arc length (mm) along the branch where its centerline leaves the parent's lumen.

    branch_X (N, 3) from the bifurcation; parent_X (P, 3) with radii (P,).
    Sought over the branch's first 4 r_max + 2 mm (r_max the parent's
    largest radius); the end of that stretch when the branch has not left
    by then (a branch running inside its parent).
    """
    s_b = arclength(branch_X)
    window = s_b <= min(s_b[-1], 4.0 * float(np.max(parent_radius_mm)) + 2.0)
    d, s_foot = _distance_to_polyline(branch_X[window], parent_X)
    r_local = np.interp(s_foot, arclength(parent_X), parent_radius_mm)
    outside = np.flatnonzero(d > r_local)
    return float(s_b[window][outside[0]] if outside.size else s_b[window][-1])


@dataclass(frozen=True, eq=False)
class Junction:
    """A branch's parent: its 3D centerline (P, 3) mm and lumen radius (P,) mm."""

    parent_X_world: FloatArray
    parent_radius_mm: FloatArray

    def join(self, cl3d: Centerline3D) -> Centerline3D:
        """The branch centerline with its start moved onto the parent's centerline.

        The shift J - X_0 is blended out with a raised cosine over the
        branch's first max(carina arc length, 1 mm) (the stretch inside the
        parent's lumen), or longer where the shift is large, so that the
        blend turns the branch by at most :data:`MAX_JOIN_TURN_DEG` (a raised
        cosine of height d over L has the steepest slope pi d / (2 L)); at most
        half the branch. Arc length and tangents are recomputed; radii and the
        raw points stay.
        """
        X = np.asarray(cl3d.X_world, dtype=float)
        J, _, _ = nearest_on_polyline(self.parent_X_world, X[0])
        s = arclength(X)
        shift_mm = float(np.linalg.norm(J - X[0]))
        blend = max(carina_s_mm(X, self.parent_X_world, self.parent_radius_mm), _MIN_BLEND_MM,
                    min(np.pi * shift_mm / (2.0 * np.tan(np.radians(MAX_JOIN_TURN_DEG))),
                        0.5 * float(s[-1])))
        w = np.where(s < blend, 0.5 * (1.0 + np.cos(np.pi * np.clip(s / blend, 0.0, 1.0))), 0.0)
        X_new = X + w[:, None] * (J - X[0])[None, :]
        T = np.gradient(X_new, axis=0)
        T /= np.maximum(np.linalg.norm(T, axis=1, keepdims=True), 1e-12)
        return replace(cl3d, X_world=X_new, s_mm=arclength(X_new), tangents=T)


def direction_away(X_world: FloatArray, s_mm: FloatArray, s_from: float, s_to: float) -> FloatArray:
    """Unit principal direction (3,) of the points with s in [s_from, s_to], pointing to s_to.

    ``s_to < s_from`` fits a stretch before ``s_from`` pointing backwards.
    Falls back to the two nearest points when the window holds fewer than 2.
    """
    lo, hi = min(s_from, s_to), max(s_from, s_to)
    inside = (s_mm >= lo) & (s_mm <= hi)
    if np.count_nonzero(inside) < 2:
        idx = np.argsort(np.abs(s_mm - 0.5 * (lo + hi)))[:2]
        inside = np.zeros(len(s_mm), dtype=bool)
        inside[idx] = True
    P = X_world[inside]
    centred = P - P.mean(axis=0)
    axis = np.linalg.svd(centred, full_matrices=False)[2][0]
    toward = np.interp(s_to, s_mm, np.arange(len(s_mm)))
    i_to = int(np.clip(round(toward), 0, len(s_mm) - 1))
    i_from = int(np.clip(round(np.interp(s_from, s_mm, np.arange(len(s_mm)))), 0, len(s_mm) - 1))
    if axis @ (X_world[i_to] - X_world[i_from]) < 0:
        axis = -axis
    return axis / np.linalg.norm(axis)


def sharpest_turn_deg(X_world: FloatArray, s_to_mm: float,
                      chord_mm: float = TURN_CHORD_MM) -> float:
    """Largest angle (deg) between successive chords of ``chord_mm`` along X_world (N, 3)
    from its start to arc length ``s_to_mm`` (or its end); 0 with fewer than two chords."""
    X = np.asarray(X_world, dtype=float)
    s = arclength(X)
    grid = np.arange(0.0, min(float(s_to_mm), float(s[-1])) + 1e-9, chord_mm)
    if len(grid) < 3:
        return 0.0
    P = np.column_stack([np.interp(grid, s, X[:, k]) for k in range(3)])  # (G, 3)
    chords = np.diff(P, axis=0)
    chords /= np.maximum(np.linalg.norm(chords, axis=1, keepdims=True), 1e-12)
    cosines = np.einsum("ij,ij->i", chords[:-1], chords[1:])
    return float(np.degrees(np.arccos(np.clip(cosines.min(), -1.0, 1.0))))


def _angle_deg(u: FloatArray, v: FloatArray) -> float:
    return float(np.degrees(np.arccos(np.clip(u @ v, -1.0, 1.0))))


def bifurcation_angles_deg(
    parent_X: FloatArray, parent_radius_mm: FloatArray, branch_X: FloatArray
) -> tuple[float, float, dict]:
    """(bifurcation angle, proximal angle) in degrees, and the geometry they came from.

    parent_X (P, 3) and its radii (P,); branch_X (N, 3) starting at the
    bifurcation (on or near the parent). The dict holds ``junction_s_mm``,
    ``junction_radius_mm``, ``carina_s_mm`` and the three unit directions.
    """
    s_p = arclength(parent_X)
    s_b = arclength(branch_X)
    _, s_j, _ = nearest_on_polyline(parent_X, branch_X[0])
    r_j = float(np.interp(s_j, s_p, parent_radius_mm))
    s_c = carina_s_mm(branch_X, parent_X, parent_radius_mm)
    w0, w1 = DIRECTION_WINDOW_MM
    side = direction_away(branch_X, s_b, s_c + w0, s_c + w1)
    distal = direction_away(parent_X, s_p, s_j + r_j + w0, s_j + r_j + w1)
    proximal = direction_away(parent_X, s_p, s_j - r_j - w0, s_j - r_j - w1)
    info = {"junction_s_mm": s_j, "junction_radius_mm": r_j, "carina_s_mm": s_c,
            "direction_proximal": proximal, "direction_distal": distal, "direction_side": side}
    return _angle_deg(distal, side), _angle_deg(proximal, side), info


@dataclass(frozen=True)
class SegmentQCA:
    """QCA of one of a bifurcation's three segments (mm, % of diameter)."""

    start_s_mm: float
    end_s_mm: float
    reference_diameter_mm: float
    mld_mm: float
    diameter_stenosis_pct: float


@dataclass(frozen=True)
class BifurcationQCA:
    """One bifurcation: its segments, angles and Medina class.

    ``proximal_main``, ``distal_main`` : on the parent (arc length of the parent);
    ``side_branch`` : on the branch (arc length of the branch);
    ``medina`` : "p,d,s" each 1 (%DS >= 50) or 0;
    ``origin_warning`` : why the branch's origin is implausible (module docstring),
    or None; ``origin_form`` : the same with ``{parent}`` and ``{branch}`` in place of
    the names (:meth:`renamed` fills them again; not reported).
    """

    name: str
    parent: str
    branch: str
    junction_world: tuple[float, float, float]
    gap_mm: float
    join_shift_mm: float
    carina_s_mm: float
    proximal_main: SegmentQCA
    distal_main: SegmentQCA
    side_branch: SegmentQCA
    bifurcation_angle_deg: float
    proximal_angle_deg: float
    medina: str
    origin_warning: str | None = None
    origin_form: str | None = None

    def to_dict(self) -> dict:
        out = asdict(self)
        del out["origin_form"]
        return out

    def renamed(self, old: str, new: str) -> BifurcationQCA:
        """This bifurcation with the segment ``old`` called ``new`` (as its parent or its
        branch), its origin warning included."""
        parent = new if self.parent == old else self.parent
        branch = new if self.branch == old else self.branch
        warning = (fill_names(self.origin_form, parent, branch) if self.origin_form is not None
                   else self.origin_warning)
        return replace(self, parent=parent, branch=branch, origin_warning=warning)


def _segment_qca(s_mm: FloatArray, diameter_mm: FloatArray, reference_mm: FloatArray,
                 start: float, end: float) -> SegmentQCA:
    lo, hi = max(min(start, end), float(s_mm[0])), min(max(start, end), float(s_mm[-1]))
    inside = (s_mm >= lo) & (s_mm <= hi)
    if not np.any(inside):
        inside[int(np.argmin(np.abs(s_mm - 0.5 * (start + end))))] = True
    idx = np.flatnonzero(inside)
    i_mld = int(idx[np.argmin(diameter_mm[idx])])
    mld = float(diameter_mm[i_mld])
    return SegmentQCA(
        start_s_mm=float(lo),
        end_s_mm=float(hi),
        reference_diameter_mm=float(np.mean(reference_mm[idx])),
        mld_mm=mld,
        diameter_stenosis_pct=float(100.0 * (1.0 - mld / reference_mm[i_mld])),
    )


def bifurcation_qca(
    name: str,
    parent: str,
    branch: str,
    parent_X: FloatArray,
    parent_profile: tuple[FloatArray, FloatArray, FloatArray],
    branch_X: FloatArray,
    branch_profile: tuple[FloatArray, FloatArray, FloatArray],
    join_shift_mm: float,
) -> BifurcationQCA:
    """Bifurcation QCA (module docstring) from the two 3D centerlines and their profiles.

    parent_X (P, 3), branch_X (N, 3) world mm; each profile is (s_mm,
    smoothed diameter_mm, reference diameter_mm), arrays of the centerline's
    length. ``join_shift_mm`` is how far the branch's start was moved to
    join the parent (reported); ``gap_mm`` in the result is the distance
    left between the branch's start and the parent's centerline.
    """
    s_p, d_p, ref_p = parent_profile
    s_b, d_b, ref_b = branch_profile
    radius_p = 0.5 * d_p
    bif, prox, info = bifurcation_angles_deg(parent_X, radius_p, branch_X)
    s_j, r_j, s_c = info["junction_s_mm"], info["junction_radius_mm"], info["carina_s_mm"]
    proximal = _segment_qca(s_p, d_p, ref_p, s_j - r_j - QCA_SEGMENT_MM, s_j - r_j)
    distal = _segment_qca(s_p, d_p, ref_p, s_j + r_j, s_j + r_j + QCA_SEGMENT_MM)
    side = _segment_qca(s_b, d_b, ref_b, s_c, s_c + QCA_SEGMENT_MM)
    medina = ",".join(str(int(q.diameter_stenosis_pct >= MEDINA_DS_PCT))
                      for q in (proximal, distal, side))
    J, _, _ = nearest_on_polyline(parent_X, branch_X[0])
    form = _origin_form(name, s_c, r_j, bif)
    return BifurcationQCA(
        name=name,
        parent=parent,
        branch=branch,
        junction_world=tuple(float(x) for x in J),
        gap_mm=float(np.linalg.norm(J - branch_X[0])),
        join_shift_mm=float(join_shift_mm),
        carina_s_mm=float(s_c),
        proximal_main=proximal,
        distal_main=distal,
        side_branch=side,
        bifurcation_angle_deg=bif,
        proximal_angle_deg=prox,
        medina=medina,
        origin_warning=fill_names(form, parent, branch),
        origin_form=form,
    )


def origin_warning(name: str, parent: str, branch: str, carina_mm: float, r_j_mm: float,
                   angle_deg: float) -> str | None:
    """One line when the carina lies farther along the branch (``carina_mm``) than
    :data:`ORIGIN_CARINA_FACTOR` times r_J / sin(angle) (module docstring), else None."""
    return fill_names(_origin_form(name, carina_mm, r_j_mm, angle_deg), parent, branch)


def _origin_form(name: str, carina_mm: float, r_j_mm: float, angle_deg: float) -> str | None:
    """:func:`origin_warning` with ``{parent}`` and ``{branch}`` left to fill."""
    expected_mm = r_j_mm / max(float(np.sin(np.radians(angle_deg))), np.sin(np.radians(5.0)))
    if carina_mm <= ORIGIN_CARINA_FACTOR * expected_mm:
        return None
    return (f"{literal(name)}: {{branch}} stays {carina_mm:.1f} mm inside {{parent}}'s lumen, "
            f"where a branch at {angle_deg:.0f} deg leaves within about {expected_mm:.1f} mm: "
            "its trace in one view likely follows {parent} first (a faint ostium skipped), so "
            "its angle and ostium are uncertain; add a waypoint on {branch} just past its "
            "origin")


def literal(text: str) -> str:
    """``text`` as the literal part of a :meth:`str.format` form (its braces doubled)."""
    return text.replace("{", "{{").replace("}", "}}")


def fill_names(form: str | None, parent: str, branch: str) -> str | None:
    """A warning's form with the parent's and the branch's names put in (None stays None)."""
    return None if form is None else form.format(parent=parent, branch=branch)
