"""The C-arm pose: calibration of view B (PALM, on landmarks and on traced curves), the
posterior over the geometry and the measurement intervals, the best next view.

The names the pipeline uses are re-exported here and loaded on first use
(so that importing one module of the package does not import the others).
"""

from __future__ import annotations

from recon import lazy_exports

# The function is named like its module, so it is bound here (a lazy name would be
# replaced by the module once the module is loaded).
from recon.pose.optimal_view import optimal_view

_EXPORTS = {
    "CORRECTIONS": "recon.pose.calibration",
    "CalibrationResult": "recon.pose.calibration",
    "calibrate": "recon.pose.calibration",
    "calibrate_supported": "recon.pose.calibration",
    "refine_with_matches": "recon.pose.calibration",
    "calibrate_with_curves": "recon.pose.calibration_curves",
    "OptimalView": "recon.pose.optimal_view",
    "calibration_step": "recon.pose.self_calibration",
    "self_calibrate": "recon.pose.self_calibration",
    "MeasurementIntervals": "recon.pose.uncertainty",
    "measurement_intervals": "recon.pose.uncertainty",
    "observability": "recon.pose.uncertainty",
}

__all__ = [*_EXPORTS, "optimal_view"]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
