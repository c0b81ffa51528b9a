"""One synthetic two-view case: :func:`make_phantom` and :class:`PhantomCase`.

The same ``(preset, seed)`` always gives the same case: four independent
random streams (header error, tree, clicks, rendering) are spawned from it,
so the stenosis percentage, ``render`` and ``n_frames`` do not change the
tree, the header error or the clicks. An imaging chain
(:mod:`recon.synth.chains`) and an anatomy variant
(:mod:`recon.synth.anatomy`) take a fifth stream of their own (the chain's
values, the guiding catheter, the variant's choices); with both None a case
is exactly the plain phantom's.

A chain modelled on a clinical export (:data:`recon.synth.chains.CLINICAL_CHAINS`)
also draws, from the same fifth stream, a guiding catheter whose shaft runs
beside the clicked segment in the faint view and a pacing lead beside the
segment, renders its faint view's vessels at the drawn
grey-level contrast, and widens the table shift of view B's header error
(the same draws, a wider range).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from recon.errors import CoronaryError
from recon.geometry import ViewGeometry
from recon.seeds import Seeds
from recon.synth.anatomy import (
    Anatomy,
    Catheter,
    Lead,
    add_crossing,
    catheter_beside,
    faint_fade,
    guiding_catheter,
    loop_crossing_views,
    pacing_lead,
    resolve_anatomy,
)
from recon.synth.chain_render import render_chain_view
from recon.synth.chains import ChainDraw, ImagingChain, draw_chain, resolve_chain
from recon.synth.clicks import HEADER_SHIFT_MM, make_seeds, random_header_error
from recon.synth.presets import PRESETS, PhantomPreset
from recon.synth.render import render_view
from recon.synth.tree import PhantomTruth, TreeDraw, draw_tree, tree_fits, truth_from_tree

__all__ = ["PhantomCase", "PhantomError", "make_phantom"]


class PhantomError(CoronaryError):
    """A phantom request that cannot be served (bad preset, unreadable truth file)."""


@dataclass(frozen=True, eq=False)
class PhantomCase:
    """One synthetic two-view case.

    Attributes
    ----------
    preset, seed : what made it.
    view_a : view A's geometry (header == truth; it defines the world).
    view_b_nominal : view B's header geometry.
    view_b_true : view B's true geometry (images and clicks are made with it).
    image_a, image_b : (H, W) float32 12-bit values (0..4095, integers), or
        None when ``render=False``; with an imaging chain, the chain's stored
        values (0..255 or 0..4095, integers) on its detector.
    frames_a, frames_b : (F, H, W) float32 cine stacks when ``n_frames > 1``,
        else None; ``image_k = frames_k[frame_index]``.
    frame_index : the frame the truth holds for (the sharpest, full contrast).
    seeds : the clinician's clicks, made with the true geometries.
    truth : the ground truth.
    chain : the imaging chain's drawn values, or None (the plain renderer).
    anatomy : the anatomy variant's name, or None (the plain tree).
    catheter : the guiding catheter rendered into both views, or None.
    anatomy_info : what the variant made: "crossing_view" ("A" or "B": where
        the crossing vessel lies over the lesion), "loop_s_mm" (the loop's
        arc-length range on the main vessel) and "loop_crossing_views" (the
        views where its projection crosses itself), "faint_distal_fraction",
        "eccentric" ((fraction, angle rad)); with a faint view (a clinical
        export chain) "faint_view" ("A" or "B") and "faint_contrast_levels".
    lead : the pacing lead rendered into both views, or None.
    """

    preset: str
    seed: int
    view_a: ViewGeometry
    view_b_nominal: ViewGeometry
    view_b_true: ViewGeometry
    image_a: NDArray[np.float32] | None
    image_b: NDArray[np.float32] | None
    seeds: Seeds
    truth: PhantomTruth
    frames_a: NDArray[np.float32] | None = None
    frames_b: NDArray[np.float32] | None = None
    frame_index: int = 0
    stenosis_pct: float = field(default=50.0)
    chain: ChainDraw | None = None
    anatomy: str | None = None
    catheter: Catheter | None = None
    anatomy_info: dict = field(default_factory=dict)
    lead: Lead | None = None


def make_phantom(
    preset: str | PhantomPreset = "data1",
    seed: int = 0,
    *,
    stenosis_pct: float = 50.0,
    render: bool = True,
    n_frames: int = 1,
    header_error: bool = True,
    chain: str | ImagingChain | None = None,
    anatomy: str | Anatomy | None = None,
    side_stenosis_pct: float = 0.0,
) -> PhantomCase:
    """Make one synthetic two-view case with its ground truth.

    Parameters
    ----------
    preset : key of :data:`PRESETS` ("data1", "data2", "data3", "static"), or a
        :class:`PhantomPreset` (any pair of geometries; its name seeds the case).
    seed : random seed; the same (preset, seed) gives an identical case.
    stenosis_pct : diameter stenosis in percent (0 <= pct < 100).
    render : also render the two images (else image_a/image_b are None).
    n_frames : frames of the cine stacks (1: no stacks; chains render one frame).
    header_error : draw a random header error of view B (else nominal == true).
    chain : an imaging chain (name in :data:`recon.synth.chains.CHAINS`): its
        detector replaces the preset's (rows, cols, pixel spacing; the field
        constraints are fractions of the image), and it renders the images.
        None: the plain renderer.
    anatomy : an anatomy variant (name in :data:`recon.synth.anatomy.ANATOMIES`);
        None: the plain tree.
    side_stenosis_pct : an ostial lesion of the first side branch (diameter
        percentage; :func:`recon.synth.tree.truth_from_tree`); 0: none.

    Returns
    -------
    PhantomCase
    """
    p = _resolve_preset(preset)
    if not 0.0 <= stenosis_pct < 100.0:
        raise PhantomError(f"stenosis_pct must be in [0, 100), got {stenosis_pct}")
    if n_frames < 1:
        raise PhantomError(f"n_frames must be at least 1, got {n_frames}")
    try:
        chain_spec = None if chain is None else resolve_chain(chain)
        anat = resolve_anatomy(anatomy)
    except ValueError as err:
        raise PhantomError(str(err)) from None
    if chain_spec is not None and n_frames != 1:
        raise PhantomError("an imaging chain renders one frame: use n_frames=1")
    ss_error, ss_tree, ss_click, ss_render = np.random.SeedSequence(
        [int(seed), _preset_key(p.name)]
    ).spawn(4)
    extra_rng = np.random.default_rng(np.random.SeedSequence([int(seed), _preset_key(p.name), 1]))
    draw = None if chain_spec is None else draw_chain(chain_spec, extra_rng)
    view_a = p.view_a if draw is None else _with_detector(p.view_a, draw)
    view_b_nominal = p.view_b if draw is None else _with_detector(p.view_b, draw)
    if header_error:
        table = chain_spec is not None and chain_spec.table_shift_mm is not None
        rotvec, t_mm = random_header_error(
            np.random.default_rng(ss_error), view_b_nominal,
            shift_mm=chain_spec.table_shift_mm if table else HEADER_SHIFT_MM,
            in_table_plane=table)
    else:
        rotvec, t_mm = np.zeros(3), np.zeros(3)
    view_b_true = view_b_nominal.with_correction(rotvec, t_mm)

    info: dict = {}
    crossing_view = None
    fade = None
    if anat is not None and anat.crossing:
        crossing_view = int(extra_rng.integers(2))
        info["crossing_view"] = "AB"[crossing_view]
    if anat is not None and anat.faint:
        fade = faint_fade(extra_rng)
        info["faint_distal_fraction"] = fade[0]
    tree = _draw_fitting_tree(np.random.default_rng(ss_tree), anat, crossing_view,
                              (view_a, view_b_true, view_b_nominal), p.name)
    if tree.loop_s is not None:
        info["loop_s_mm"] = tree.loop_s
        info["loop_crossing_views"] = tuple(
            "AB"[k] for k in loop_crossing_views(tree.main_X, tree.loop_s, (view_a, view_b_true))
        )
    if tree.eccentric is not None:
        info["eccentric"] = tree.eccentric

    truth, branch_names = truth_from_tree(tree, stenosis_pct, rotvec, t_mm, side_stenosis_pct)
    seeds = make_seeds(
        np.random.default_rng(ss_click),
        truth.segment_X_world,
        truth.features_world[2:],
        branch_names,
        view_a,
        view_b_true,
    )
    catheter = None
    if draw is not None and "catheter" in draw.background and draw.faint_view is not None:
        catheter = catheter_beside(extra_rng, truth.vessels[0][0], truth.segment_X_world,
                                   (view_a, view_b_true), "AB".index(draw.faint_view))
    elif draw is not None and "catheter" in draw.background:
        catheter = guiding_catheter(extra_rng, truth.vessels[0][0], (view_a, view_b_true))
    lead = None
    if draw is not None and "lead" in draw.background:
        lead = pacing_lead(extra_rng, truth.segment_X_world, (view_a, view_b_true))
    if draw is not None and draw.faint_view is not None:
        info["faint_view"] = draw.faint_view
        info["faint_contrast_levels"] = draw.faint_contrast_levels
    image_a = image_b = frames_a = frames_b = None
    frame_index = 0
    if render and draw is not None:
        rrng = np.random.default_rng(ss_render)
        kwargs = {"catheter": catheter} if fade is None else {"catheter": catheter, "fade": fade}
        if lead is not None:
            kwargs["lead"] = lead
        faint = {"contrast_levels": draw.faint_contrast_levels,
                 "contrast_X_world": truth.segment_X_world}
        image_a = render_chain_view(rrng, view_a, truth.vessels, draw, **kwargs,
                                    **(faint if draw.faint_view == "A" else {}))
        image_b = render_chain_view(rrng, view_b_true, truth.vessels, draw, **kwargs,
                                    **(faint if draw.faint_view == "B" else {}))
    elif render:
        rrng = np.random.default_rng(ss_render)
        frames_a, frame_index = render_view(rrng, view_a, truth.vessels, n_frames, fade)
        frames_b, _ = render_view(rrng, view_b_true, truth.vessels, n_frames, fade)
        image_a, image_b = frames_a[frame_index], frames_b[frame_index]
        if n_frames == 1:
            frames_a = frames_b = None
    return PhantomCase(
        preset=p.name,
        seed=int(seed),
        view_a=view_a,
        view_b_nominal=view_b_nominal,
        view_b_true=view_b_true,
        image_a=image_a,
        image_b=image_b,
        seeds=seeds,
        truth=truth,
        frames_a=frames_a,
        frames_b=frames_b,
        frame_index=frame_index,
        stenosis_pct=float(stenosis_pct),
        chain=draw,
        anatomy=None if anat is None else anat.name,
        catheter=catheter,
        anatomy_info=info,
        lead=lead,
    )


#: Tree draws tried before a case gives up (the plain tree needs a few).
MAX_TREE_DRAWS = 5000


def _draw_fitting_tree(
    rng: np.random.Generator, anat: Anatomy | None, crossing_view: int | None,
    views: tuple[ViewGeometry, ViewGeometry, ViewGeometry], name: str,
) -> TreeDraw:
    """The first tree draw (with the variant's options) that fits every view.

    ``views`` = (A, B true, B nominal). A loop must cross itself in the
    projection of A or B; a crossing vessel is added in ``crossing_view``.
    """
    flags = {}
    if anat is not None:
        flags = {"loop": anat.loop, "branch_stenosis": anat.branch_stenosis,
                 "eccentric": anat.eccentric}
    for _ in range(MAX_TREE_DRAWS):
        tree = draw_tree(rng, **flags)
        if tree is None:
            continue
        if crossing_view is not None:
            tree = add_crossing(tree, rng, views[:2], crossing_view)
            if tree is None:
                continue
        if not tree_fits(tree, views):
            continue
        if tree.loop_s is not None and not loop_crossing_views(tree.main_X, tree.loop_s,
                                                                views[:2]):
            continue
        return tree
    raise PhantomError(f"could not draw a tree inside the field for preset {name!r}")


def _resolve_preset(preset: str | PhantomPreset) -> PhantomPreset:
    if isinstance(preset, PhantomPreset):
        return preset
    if preset not in PRESETS:
        raise PhantomError(f"unknown phantom preset {preset!r} (use one of {', '.join(PRESETS)})")
    return PRESETS[preset]


def _with_detector(view: ViewGeometry, draw: ChainDraw) -> ViewGeometry:
    """The view on the chain's detector (rows, cols, square pixel spacing)."""
    sp = float(draw.pixel_spacing_mm)
    return replace(view, rows=draw.rows, cols=draw.cols, pixel_spacing_mm=(sp, sp))


def _preset_key(preset: str) -> int:
    return sum((k + 1) * ord(c) for k, c in enumerate(preset))

