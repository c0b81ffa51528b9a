"""C-arm projection geometry, two-view relations and triangulation.

Implements exactly the convention of the project's C-arm geometry note
(world = DICOM patient LPS in mm, origin at the isocenter; pixel (col, row),
0-based, (0, 0) the centre of the top-left pixel):

    d = ( sin a cos b, -cos a cos b, sin b )     isocenter -> detector centre
    u = ( cos a, sin a, 0 )                       image column axis
    v = u x d                                     image row axis
    S = -SOD d                                    X-ray source
    col = cx + SID (X - S).u / ((X - S).d sc)
    row = cy + SID (X - S).v / ((X - S).d sr)

A view may carry a rigid correction of its whole C-arm rig (source and
detector moved together), ``x -> R_corr x + t_corr``, with R_corr a rotation
about the isocenter. Calibration estimates this correction for view B.

Paper references are to Tong et al., "3D Reconstruction with Coronary
Artery Based on Curve Descriptor and Projection Geometry-Constrained
Vasculature Matching" (the seed paper): eq. (1) relative pose, eqs. (2)-(3)
least-squares triangulation, eq. (4) epipolar line, eq. (8) point-to-line
distance.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "ViewGeometry",
    "rotation_from_rotvec",
    "rotvec_from_rotation",
    "relative_pose",
    "fundamental_matrix",
    "epipolar_lines",
    "point_line_distance_px",
    "triangulate_dlt",
    "triangulate_paper",
    "triangulate",
    "ray_distance_mm",
    "view_separation_deg",
    "MIN_VIEW_SEPARATION_DEG",
]

FloatArray = NDArray[np.float64]


def rotation_from_rotvec(rotvec: ArrayLike) -> FloatArray:
    """Rotation matrix (3, 3) from a rotation vector (3,) in radians (Rodrigues)."""
    r = np.asarray(rotvec, dtype=float).reshape(3)
    theta = float(np.linalg.norm(r))
    kx = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
    if theta < 1e-12:
        return np.eye(3) + kx
    kx /= theta
    return np.eye(3) + np.sin(theta) * kx + (1.0 - np.cos(theta)) * (kx @ kx)


def rotvec_from_rotation(R: ArrayLike) -> FloatArray:
    """Rotation vector (3,) in radians from a rotation matrix (3, 3)."""
    R = np.asarray(R, dtype=float)
    cos_t = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
    theta = float(np.arccos(cos_t))
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if theta < 1e-8:
        return w / 2.0
    if np.pi - theta < 1e-6:  # near 180 degrees: axis from the symmetric part
        axis = np.sqrt(np.clip((np.diag(R) + 1.0) / 2.0, 0.0, None))
        axis *= np.where(w >= 0, 1.0, -1.0)
        return axis / np.linalg.norm(axis) * theta
    return w * theta / (2.0 * np.sin(theta))


@dataclass(frozen=True)
class ViewGeometry:
    """Geometry of one C-arm view.

    Attributes
    ----------
    alpha_deg, beta_deg : primary (LAO +, RAO -) and secondary (CRA +, CAU -)
        positioner angles in degrees.
    sid_mm, sod_mm : source-to-detector and source-to-isocenter distances.
    pixel_spacing_mm : (row, column) detector pixel size (ImagerPixelSpacing).
    rows, cols : image size in pixels.
    principal_offset_px : (col, row) shift of the principal point from the
        image centre ((cols - 1) / 2, (rows - 1) / 2).
    rotvec_corr : rotation vector (rad) of the rigid rig correction, about
        the isocenter.
    t_corr_mm : translation (mm) of the rigid rig correction.
    """

    alpha_deg: float
    beta_deg: float
    sid_mm: float
    sod_mm: float
    pixel_spacing_mm: tuple[float, float]
    rows: int
    cols: int
    principal_offset_px: tuple[float, float] = (0.0, 0.0)
    rotvec_corr: tuple[float, float, float] = (0.0, 0.0, 0.0)
    t_corr_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        for name in ("sid_mm", "sod_mm"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
        if self.sod_mm >= self.sid_mm:
            raise ValueError(
                f"sod_mm ({self.sod_mm}) must be smaller than sid_mm ({self.sid_mm})"
            )
        sr, sc = self.pixel_spacing_mm
        if not (sr > 0 and sc > 0):
            raise ValueError(f"pixel_spacing_mm must be positive, got {self.pixel_spacing_mm}")
        if self.rows <= 0 or self.cols <= 0:
            raise ValueError(f"image size must be positive, got {self.rows}x{self.cols}")
        # Normalise tuple fields so that equal geometries compare equal.
        object.__setattr__(self, "pixel_spacing_mm", (float(sr), float(sc)))
        object.__setattr__(
            self, "principal_offset_px", tuple(float(x) for x in self.principal_offset_px)
        )
        object.__setattr__(self, "rotvec_corr", tuple(float(x) for x in self.rotvec_corr))
        object.__setattr__(self, "t_corr_mm", tuple(float(x) for x in self.t_corr_mm))

    # ------------------------------------------------------------------ axes
    @cached_property
    def nominal_axes(self) -> FloatArray:
        """Rows u, v, d (3, 3) of the uncorrected view, from the angles."""
        a = np.deg2rad(self.alpha_deg)
        b = np.deg2rad(self.beta_deg)
        d = np.array([np.sin(a) * np.cos(b), -np.cos(a) * np.cos(b), np.sin(b)])
        u = np.array([np.cos(a), np.sin(a), 0.0])
        v = np.cross(u, d)
        return np.stack([u, v, d])

    @cached_property
    def R_corr(self) -> FloatArray:
        """Rotation (3, 3) of the rigid rig correction."""
        return rotation_from_rotvec(self.rotvec_corr)

    @cached_property
    def R_view_from_world(self) -> FloatArray:
        """Rotation (3, 3) whose rows are the view's u, v, d in world coordinates."""
        return self.nominal_axes @ self.R_corr.T

    @cached_property
    def source_world(self) -> FloatArray:
        """X-ray source position (3,) in world mm."""
        s_nominal = -self.sod_mm * self.nominal_axes[2]
        return self.R_corr @ s_nominal + np.asarray(self.t_corr_mm)

    @cached_property
    def detector_centre_world(self) -> FloatArray:
        """Detector centre (3,) in world mm."""
        d_nominal = (self.sid_mm - self.sod_mm) * self.nominal_axes[2]
        return self.R_corr @ d_nominal + np.asarray(self.t_corr_mm)

    @property
    def pixel_mm_at_isocenter(self) -> float:
        """Size (mm) of one detector pixel at the isocenter: mean spacing x SOD / SID."""
        return float(np.mean(self.pixel_spacing_mm)) * self.sod_mm / self.sid_mm

    @property
    def centre_px(self) -> tuple[float, float]:
        """Principal point (col, row) in pixels."""
        return (
            (self.cols - 1) / 2.0 + self.principal_offset_px[0],
            (self.rows - 1) / 2.0 + self.principal_offset_px[1],
        )

    @cached_property
    def K(self) -> FloatArray:
        """Intrinsic matrix (3, 3): [[SID/sc, 0, cx], [0, SID/sr, cy], [0, 0, 1]]."""
        sr, sc = self.pixel_spacing_mm
        cx, cy = self.centre_px
        return np.array([[self.sid_mm / sc, 0.0, cx], [0.0, self.sid_mm / sr, cy], [0, 0, 1.0]])

    @cached_property
    def P(self) -> FloatArray:
        """Projection matrix (3, 4) = K [R | -R S]."""
        R = self.R_view_from_world
        return self.K @ np.hstack([R, (-R @ self.source_world)[:, None]])

    # ------------------------------------------------------------ projection
    def to_view_frame(self, X_world: ArrayLike) -> FloatArray:
        """World points (N, 3) -> view-frame coordinates (N, 3) (origin at source)."""
        X = _as_points(X_world, 3, "X_world")
        return (X - self.source_world) @ self.R_view_from_world.T

    def project(self, X_world: ArrayLike) -> FloatArray:
        """Project world points (N, 3) in mm to pixels (N, 2) as (col, row)."""
        x = self.to_view_frame(X_world)
        sr, sc = self.pixel_spacing_mm
        cx, cy = self.centre_px
        w = x[:, 2]
        return np.stack(
            [cx + self.sid_mm * x[:, 0] / (w * sc), cy + self.sid_mm * x[:, 1] / (w * sr)],
            axis=1,
        )

    def depth_mm(self, X_world: ArrayLike) -> FloatArray:
        """Depth (N,) of world points along the central ray, from the source."""
        return self.to_view_frame(X_world)[:, 2]

    def normalized_coords(self, points_px: ArrayLike) -> FloatArray:
        """Pixels (N, 2) -> normalised image coordinates (N, 2) (xi, eta) = (x/z, y/z)."""
        p = _as_points(points_px, 2, "points_px")
        sr, sc = self.pixel_spacing_mm
        cx, cy = self.centre_px
        return np.stack(
            [(p[:, 0] - cx) * sc / self.sid_mm, (p[:, 1] - cy) * sr / self.sid_mm], axis=1
        )

    def ray_directions(self, points_px: ArrayLike) -> FloatArray:
        """Unit world directions (N, 3) of the rays from the source through pixels."""
        m = self.normalized_coords(points_px)
        dirs_view = np.column_stack([m, np.ones(len(m))])
        dirs = dirs_view @ self.R_view_from_world  # = (R^T m)^T
        return dirs / np.linalg.norm(dirs, axis=1, keepdims=True)

    def detector_point_world(self, points_px: ArrayLike) -> FloatArray:
        """World position (N, 3) of pixels on the detector plane."""
        m = self.normalized_coords(points_px)
        x_view = np.column_stack([m, np.ones(len(m))]) * self.sid_mm
        return x_view @ self.R_view_from_world + self.source_world

    # ------------------------------------------------------------ changes
    def with_correction(self, rotvec: ArrayLike, t_mm: ArrayLike) -> ViewGeometry:
        """This view with a further rigid correction x -> R x + t applied after its own."""
        R_new = rotation_from_rotvec(rotvec)
        R_total = R_new @ self.R_corr
        t_total = R_new @ np.asarray(self.t_corr_mm) + np.asarray(t_mm, dtype=float)
        return replace(
            self,
            rotvec_corr=tuple(rotvec_from_rotation(R_total)),
            t_corr_mm=tuple(t_total),
        )

    def nominal(self) -> ViewGeometry:
        """This view without any rigid correction (the header geometry)."""
        return replace(self, rotvec_corr=(0.0, 0.0, 0.0), t_corr_mm=(0.0, 0.0, 0.0))

    def to_dict(self) -> dict:
        """JSON-ready description of the view."""
        return {
            "alpha_deg": self.alpha_deg,
            "beta_deg": self.beta_deg,
            "sid_mm": self.sid_mm,
            "sod_mm": self.sod_mm,
            "pixel_spacing_mm": list(self.pixel_spacing_mm),
            "rows": self.rows,
            "cols": self.cols,
            "principal_offset_px": list(self.principal_offset_px),
            "rotvec_corr": list(self.rotvec_corr),
            "t_corr_mm": list(self.t_corr_mm),
        }

    @classmethod
    def from_dict(cls, data: dict) -> ViewGeometry:
        """Inverse of :meth:`to_dict` (missing correction fields default to zero)."""
        return cls(
            alpha_deg=float(data["alpha_deg"]),
            beta_deg=float(data["beta_deg"]),
            sid_mm=float(data["sid_mm"]),
            sod_mm=float(data["sod_mm"]),
            pixel_spacing_mm=tuple(float(x) for x in data["pixel_spacing_mm"]),
            rows=int(data["rows"]),
            cols=int(data["cols"]),
            principal_offset_px=tuple(data.get("principal_offset_px", (0.0, 0.0))),
            rotvec_corr=tuple(data.get("rotvec_corr", (0.0, 0.0, 0.0))),
            t_corr_mm=tuple(data.get("t_corr_mm", (0.0, 0.0, 0.0))),
        )


def _as_points(points: ArrayLike, dim: int, name: str) -> FloatArray:
    arr = np.asarray(points, dtype=float)
    if arr.ndim == 1 and arr.shape[0] == dim:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise ValueError(f"{name} must have shape (N, {dim}), got {arr.shape}")
    return arr


# ---------------------------------------------------------------- two views
def relative_pose(view_a: ViewGeometry, view_b: ViewGeometry) -> tuple[FloatArray, FloatArray]:
    """Relative pose of eq. (1): x_b = R (x_a - t), x_k the view-frame coordinates.

    Returns R (3, 3) and t (3,) in view A's frame (mm): t is B's source seen from A.
    """
    Ra, Rb = view_a.R_view_from_world, view_b.R_view_from_world
    R = Rb @ Ra.T
    t = Ra @ (view_b.source_world - view_a.source_world)
    return R, t


def fundamental_matrix(view_a: ViewGeometry, view_b: ViewGeometry) -> FloatArray:
    """Fundamental matrix F (3, 3) with x_b^T F x_a = 0 for homogeneous pixels.

    From eq. (1): the essential matrix in normalised coordinates is
    E = R [t]_x, and F = K_b^-T E K_a^-1.
    """
    R, t = relative_pose(view_a, view_b)
    tx = np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])
    E = R @ tx
    F = np.linalg.inv(view_b.K).T @ E @ np.linalg.inv(view_a.K)
    return F / np.linalg.norm(F)


def epipolar_lines(
    points_a_px: ArrayLike, view_a: ViewGeometry, view_b: ViewGeometry
) -> FloatArray:
    """Epipolar lines (N, 3) in view B of pixels (N, 2) of view A (eq. 4).

    Each line (a, b, c) satisfies a col + b row + c = 0 and is scaled so that
    a^2 + b^2 = 1: ``lines @ [col, row, 1]`` is then the signed distance in px.
    """
    p = _as_points(points_a_px, 2, "points_a_px")
    F = fundamental_matrix(view_a, view_b)
    lines = np.column_stack([p, np.ones(len(p))]) @ F.T
    return lines / np.linalg.norm(lines[:, :2], axis=1, keepdims=True)


def point_line_distance_px(lines: ArrayLike, points_px: ArrayLike) -> FloatArray:
    """Distance matrix (N, M) from normalised lines (N, 3) to points (M, 2) (eq. 8)."""
    L = np.asarray(lines, dtype=float)
    p = _as_points(points_px, 2, "points_px")
    return np.abs(L[:, :2] @ p.T + L[:, 2:3])


def triangulate_paper(
    points_a_px: ArrayLike, points_b_px: ArrayLike, view_a: ViewGeometry, view_b: ViewGeometry
) -> FloatArray:
    """Least-squares triangulation of eqs. (2)-(3), vectorised over N pairs.

    In view A's frame, with (xi, eta) the normalised coordinates, solve
    [1 0 -xi_a; 0 1 -eta_a; a; b] x_a = [0; 0; a.t; b.t] by the normal
    equations C = (A^T A)^-1 A^T B (eq. 3), then return world points (N, 3).
    """
    ma = view_a.normalized_coords(points_a_px)
    mb = view_b.normalized_coords(points_b_px)
    if len(ma) != len(mb):
        raise ValueError(f"point counts differ: {len(ma)} in A, {len(mb)} in B")
    R, t = relative_pose(view_a, view_b)
    n = len(ma)
    A = np.zeros((n, 4, 3))
    A[:, 0, 0] = 1.0
    A[:, 0, 2] = -ma[:, 0]
    A[:, 1, 1] = 1.0
    A[:, 1, 2] = -ma[:, 1]
    A[:, 2, :] = R[0] - mb[:, 0:1] * R[2]  # eq. (2): vector a
    A[:, 3, :] = R[1] - mb[:, 1:2] * R[2]  # eq. (2): vector b
    B = np.zeros((n, 4))
    B[:, 2] = A[:, 2, :] @ t
    B[:, 3] = A[:, 3, :] @ t
    AtA = np.einsum("nki,nkj->nij", A, A)
    AtB = np.einsum("nki,nk->ni", A, B)
    x_a = np.linalg.solve(AtA, AtB[..., None])[..., 0]  # eq. (3)
    return x_a @ view_a.R_view_from_world + view_a.source_world


def triangulate_dlt(
    points_a_px: ArrayLike, points_b_px: ArrayLike, view_a: ViewGeometry, view_b: ViewGeometry
) -> FloatArray:
    """Linear (DLT) triangulation from the two projection matrices; (N, 3) world mm.

    Each pixel is first normalised (K^-1) so the 4x4 systems are well scaled.
    """
    pa = _as_points(points_a_px, 2, "points_a_px")
    pb = _as_points(points_b_px, 2, "points_b_px")
    if len(pa) != len(pb):
        raise ValueError(f"point counts differ: {len(pa)} in A, {len(pb)} in B")
    rows = []
    for view, p in ((view_a, pa), (view_b, pb)):
        m = view.normalized_coords(p)
        R = view.R_view_from_world
        Pn = np.hstack([R, (-R @ view.source_world)[:, None]])  # K^-1 P
        rows.append(m[:, 0:1] * Pn[2] - Pn[0])
        rows.append(m[:, 1:2] * Pn[2] - Pn[1])
    A = np.stack(rows, axis=1)  # (N, 4, 4)
    _, _, vt = np.linalg.svd(A)
    Xh = vt[:, -1, :]
    return Xh[:, :3] / Xh[:, 3:4]


def triangulate(
    points_a_px: ArrayLike,
    points_b_px: ArrayLike,
    view_a: ViewGeometry,
    view_b: ViewGeometry,
    method: str = "paper",
) -> FloatArray:
    """Triangulate matched pixels (N, 2), (N, 2) to world points (N, 3) in mm.

    ``method`` is "paper" (eqs. 2-3) or "dlt".
    """
    if method == "paper":
        return triangulate_paper(points_a_px, points_b_px, view_a, view_b)
    if method == "dlt":
        return triangulate_dlt(points_a_px, points_b_px, view_a, view_b)
    raise ValueError(f"unknown triangulation method {method!r} (use 'paper' or 'dlt')")


def ray_distance_mm(
    points_a_px: ArrayLike, points_b_px: ArrayLike, view_a: ViewGeometry, view_b: ViewGeometry
) -> FloatArray:
    """Shortest distance (N,) in mm between the two back-projected rays of each pair."""
    da = view_a.ray_directions(points_a_px)
    db = view_b.ray_directions(points_b_px)
    n = np.cross(da, db)
    n_norm = np.linalg.norm(n, axis=1)
    w = view_b.source_world - view_a.source_world
    parallel = n_norm < 1e-12
    dist = np.abs(n @ w) / np.where(parallel, 1.0, n_norm)
    if np.any(parallel):
        dist[parallel] = np.linalg.norm(np.cross(w, da[parallel]), axis=1)
    return dist


#: Least angle (deg) between the two views' central rays that a reconstruction accepts
#: without being told to go on (the limit named in issue 14 of the project; the README
#: recommends views at least this far apart).
MIN_VIEW_SEPARATION_DEG = 25.0


def view_separation_deg(view_a: ViewGeometry, view_b: ViewGeometry) -> float:
    """Angle in degrees between the two central rays (small: ill-conditioned)."""
    ca = view_a.R_view_from_world[2]
    cb = view_b.R_view_from_world[2]
    return float(np.degrees(np.arccos(np.clip(ca @ cb, -1.0, 1.0))))
