"""What the benchmarks share: the preset cycle and the true-pose error of a view.

The pose error compares a view's rigid rig correction with the true one
(:meth:`recon.geometry.ViewGeometry.with_correction`: the rig maps its own
frame into the world by ``x -> R_corr x + t_corr``):

- rotation: the angle of ``R_est R_true^T``;
- displacement: the mean distance the given world points move under the
  rig error, i.e. the motion ``T_est T_true^-1`` that carries the true rig
  onto the estimated one: a point fixed to the true rig at X lands at
  ``R_est R_true^T (X - t_true) + t_est``. This is how far the points move
  relative to the view's rig, so how far their rays are off.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from recon.geometry import ViewGeometry, rotvec_from_rotation

__all__ = ["PRESET_CYCLE", "pose_error"]

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
