"""Synthetic two-view coronary phantom with exact ground truth.

Every benchmark and the demo stand on this generator. One call,
:func:`make_phantom`, draws a random coronary tree on a heart-sized
ellipsoid, a stenosis of a given diameter percentage, a random error of view
B's header geometry, the clinician's clicks (seeds) and, optionally, the two
rendered X-ray images. It returns arrays and dataclasses only; the case's
files (a.dcm, b.dcm, seeds.json, truth.json) are written by
:func:`recon.io.write_phantom_case`.

Modules: :mod:`~recon.synth.presets` (the C-arm presets),
:mod:`~recon.synth.tree` (the tree and its truth), :mod:`~recon.synth.clicks`
(header error and clicks), :mod:`~recon.synth.render` (the X-ray images),
:mod:`~recon.synth.case` (:func:`make_phantom`). The varied suite adds
:mod:`~recon.synth.chains` (imaging chains: detector, mapping, blur,
scatter / glare, noise, background, bit depth), :mod:`~recon.synth.background`
(ribs, diaphragm, table edge in mm), :mod:`~recon.synth.chain_render`
(rendering through a chain, a JPEG export), :mod:`~recon.synth.anatomy`
(harder anatomy, the guiding catheter, a pacing lead) and
:mod:`~recon.synth.suites` (:func:`varied_cases`).

Frames and conventions
----------------------
World = view A's frame (DICOM LPS, mm, isocenter origin; see
:mod:`recon.geometry`). View A's header is its true geometry. View B's
header (``view_b_nominal``) is off by a rigid rig correction:
``view_b_true = view_b_nominal.with_correction(truth.correction_rotvec,
truth.correction_t_mm)``; images and clicks are made with the TRUE
geometries, the DICOM header of b.dcm holds the NOMINAL one.

Ground truth a benchmark uses
-----------------------------
- true projected centerline of view k: ``view_k_true.project(segment_X_world)``
  (or :meth:`PhantomTruth.segment_px`);
- true projected radius in px: ``radius_mm * SID / depth / spacing`` with
  ``depth = view.depth_mm(X)`` along the central ray
  (:meth:`PhantomTruth.segment_radius_px`);
- calibration: the correction above; ``features_world`` rows are in the
  order of ``Seeds.correspondences()`` (segment ends, then bifurcations).
"""

from __future__ import annotations

from recon.synth.anatomy import ANATOMIES, ANATOMY_CYCLE, Anatomy
from recon.synth.case import PhantomCase, PhantomError, make_phantom
from recon.synth.chains import ALL_CHAINS, CHAINS, VARIED_CHAINS, ChainDraw, ImagingChain
from recon.synth.clicks import (
    CLICK_NOISE_PX,
    HEADER_ANGLE_ERROR_DEG,
    HEADER_SHIFT_MM,
    HEADER_SOD_ERROR_MM,
    click_px,
    random_header_error,
)
from recon.synth.presets import PRESETS, PhantomPreset
from recon.synth.render import path_length_image
from recon.synth.suites import SuiteCase, make_suite_case, varied_cases
from recon.synth.tree import PhantomTruth

__all__ = [
    "PhantomPreset",
    "PhantomTruth",
    "PhantomCase",
    "PhantomError",
    "PRESETS",
    "make_phantom",
    "random_header_error",
    "path_length_image",
    "HEADER_ANGLE_ERROR_DEG",
    "HEADER_SOD_ERROR_MM",
    "HEADER_SHIFT_MM",
    "CLICK_NOISE_PX",
    "click_px",
    "ImagingChain",
    "ChainDraw",
    "CHAINS",
    "ALL_CHAINS",
    "VARIED_CHAINS",
    "Anatomy",
    "ANATOMIES",
    "ANATOMY_CYCLE",
    "SuiteCase",
    "varied_cases",
    "make_suite_case",
]
