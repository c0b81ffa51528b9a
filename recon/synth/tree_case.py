"""A tree-suite case: a phantom with a bifurcation lesion, and its branches clicked.

:func:`make_tree_case` draws a phantom (:func:`recon.synth.case.make_phantom`) whose
main vessel carries a lesion at a branch origin, and clicks the side branches.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from recon.lumen.bifurcation import nearest_on_polyline as nearest_on_polyline_3d
from recon.seeds import Seeds, Segment
from recon.synth.case import make_phantom
from recon.synth.clicks import click_px
from recon.synth.presets import PhantomPreset
from recon.synth.tree import SAMPLE_STEP_MM

TREE_LESIONS = ("shoulder", "ostium", "both")
BRANCH_CLICK_FRACTIONS = (0.4, 0.75)  # waypoint and distal click, fraction of the branch
BRANCH_MIN_INSIDE_MM = 8.0  # a branch is clicked when it leaves the segment this far inside


@dataclass(frozen=True, eq=False)
class TreeCase:
    """A phantom case with every usable branch clicked as a segment of the seeds.

    ``seeds`` : version-2 seeds: segment 0 the main segment, then one branch
    per usable side branch (parent "main", bifurcation "bifurcation k").
    ``vessels`` : for each segment, the index of its vessel in
    ``case.truth.vessels``. ``end_s_mm`` : for each segment, the arc length
    on that vessel of its distal click's true point (a branch starts at 0).
    """

    case: object  # recon.synth.case.PhantomCase
    seeds: Seeds
    lesion: str
    vessels: tuple[int, ...]
    end_s_mm: tuple[float, ...]


def tree_seeds(rng: np.random.Generator, case) -> tuple[Seeds, tuple[int, ...], tuple[float, ...]]:
    """The case's seeds with each side branch that leaves the main segment at least
    :data:`BRANCH_MIN_INSIDE_MM` inside it added as a branch segment.

    A branch's first click in each view is its bifurcation's click (the
    clinician adds the branch from the bifurcation), then a waypoint and the
    distal click at :data:`BRANCH_CLICK_FRACTIONS` of the branch, true
    projections through :func:`recon.synth.clicks.click_px`.
    """
    truth = case.truth
    main = case.seeds.segments[0]
    s0 = truth.segment_start_s_mm
    s1 = s0 + truth.segment_length_mm
    main_X = truth.vessels[0][0]
    segments = [main]
    vessels = [0]
    end_s = [s1]
    features = {f.name: f for f in case.seeds.features}
    for k, name in enumerate(truth.vessel_names[1:], start=1):
        if not name.startswith("branch "):
            continue
        Xb = truth.vessels[k][0]
        feature = features.get(f"bifurcation {name.split()[1]}")
        _, s_origin, _ = nearest_on_polyline_3d(main_X, Xb[0])
        margin = BRANCH_MIN_INSIDE_MM
        if feature is None or not s0 + margin <= s_origin <= s1 - margin:
            continue
        idx = [int(round(f * (len(Xb) - 1))) for f in BRANCH_CLICK_FRACTIONS]
        clicks = {}
        for key, view, first in (("a", case.view_a, feature.a_px),
                                 ("b", case.view_b_true, feature.b_px)):
            pts = click_px(rng, view.project(Xb[idx]))
            clicks[key] = (tuple(first), *[(round(float(c), 1), round(float(r), 1))
                                           for c, r in pts])
        segments.append(Segment(name=name, a_px=clicks["a"], b_px=clicks["b"], parent=main.name,
                                bifurcation=feature.name))
        vessels.append(k)
        end_s.append(idx[-1] * SAMPLE_STEP_MM)
    return (Seeds(segments=tuple(segments), features=case.seeds.features), tuple(vessels),
            tuple(end_s))


def make_tree_case(preset: str | PhantomPreset, seed: int, lesion: str, stenosis_pct: float = 50.0,
                   render: bool = True, chain: str | None = None) -> TreeCase:
    """A tree-suite case: :func:`recon.synth.case.make_phantom` with a bifurcation
    lesion (:data:`TREE_LESIONS`) and its branches clicked (:func:`tree_seeds`).

    ``preset`` is a preset name or a :class:`recon.synth.presets.PhantomPreset`
    (a random pair); ``chain`` an imaging chain's name (None: the plain renderer).
    """
    if lesion not in TREE_LESIONS:
        raise ValueError(f"unknown lesion {lesion!r} (use one of {', '.join(TREE_LESIONS)})")
    case = make_phantom(
        preset, seed, stenosis_pct=stenosis_pct, render=render, chain=chain,
        anatomy="branch-stenosis" if lesion in ("shoulder", "both") else None,
        side_stenosis_pct=stenosis_pct if lesion in ("ostium", "both") else 0.0,
    )
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 15]))
    seeds, vessels, end_s = tree_seeds(rng, case)
    return TreeCase(case=case, seeds=seeds, lesion=lesion, vessels=vessels, end_s_mm=end_s)
