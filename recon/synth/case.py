"""One synthetic two-view case: :func:`make_phantom` and :class:`PhantomCase`.

The same ``(preset, seed)`` always gives the same case: four independent
random streams (header error, tree, clicks, rendering) are spawned from it,
so the stenosis percentage, ``render`` and ``n_frames`` do not change the
tree, the header error or the clicks.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from recon.errors import CoronaryError
from recon.geometry import ViewGeometry
from recon.seeds import Seeds
from recon.synth.clicks import make_seeds, random_header_error
from recon.synth.presets import PRESETS
from recon.synth.render import render_view
from recon.synth.tree import PhantomTruth, draw_tree, tree_fits, truth_from_tree

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
        None when ``render=False``.
    frames_a, frames_b : (F, H, W) float32 cine stacks when ``n_frames > 1``,
        else None; ``image_k = frames_k[frame_index]``.
    frame_index : the frame the truth holds for (the sharpest, full contrast).
    seeds : the clinician's clicks, made with the true geometries.
    truth : the ground truth.
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


def make_phantom(
    preset: str = "data1",
    seed: int = 0,
    *,
    stenosis_pct: float = 50.0,
    render: bool = True,
    n_frames: int = 1,
    header_error: bool = True,
) -> PhantomCase:
    """Make one synthetic two-view case with its ground truth.

    Parameters
    ----------
    preset : key of :data:`PRESETS` ("data1", "data2", "data3", "static").
    seed : random seed; the same (preset, seed) gives an identical case.
    stenosis_pct : diameter stenosis in percent (0 <= pct < 100).
    render : also render the two images (else image_a/image_b are None).
    n_frames : frames of the cine stacks (1: no stacks).
    header_error : draw a random header error of view B (else nominal == true).

    Returns
    -------
    PhantomCase
    """
    if preset not in PRESETS:
        raise PhantomError(f"unknown phantom preset {preset!r} (use one of {', '.join(PRESETS)})")
    if not 0.0 <= stenosis_pct < 100.0:
        raise PhantomError(f"stenosis_pct must be in [0, 100), got {stenosis_pct}")
    if n_frames < 1:
        raise PhantomError(f"n_frames must be at least 1, got {n_frames}")
    p = PRESETS[preset]
    ss_error, ss_tree, ss_click, ss_render = np.random.SeedSequence(
        [int(seed), _preset_key(preset)]
    ).spawn(4)
    view_a = p.view_a
    view_b_nominal = p.view_b
    if header_error:
        rotvec, t_mm = random_header_error(np.random.default_rng(ss_error), view_b_nominal)
    else:
        rotvec, t_mm = np.zeros(3), np.zeros(3)
    view_b_true = view_b_nominal.with_correction(rotvec, t_mm)

    rng = np.random.default_rng(ss_tree)
    for _ in range(2000):
        tree = draw_tree(rng)
        if tree is not None and tree_fits(tree, (view_a, view_b_true, view_b_nominal)):
            break
    else:  # pragma: no cover - the constraints are loose enough in practice
        raise PhantomError(f"could not draw a tree inside the field for preset {preset!r}")

    truth, branch_names = truth_from_tree(tree, stenosis_pct, rotvec, t_mm)
    seeds = make_seeds(
        np.random.default_rng(ss_click),
        truth.segment_X_world,
        truth.features_world[2:],
        branch_names,
        view_a,
        view_b_true,
    )
    image_a = image_b = frames_a = frames_b = None
    frame_index = 0
    if render:
        rrng = np.random.default_rng(ss_render)
        frames_a, frame_index = render_view(rrng, view_a, truth.vessels, n_frames)
        frames_b, _ = render_view(rrng, view_b_true, truth.vessels, n_frames)
        image_a, image_b = frames_a[frame_index], frames_b[frame_index]
        if n_frames == 1:
            frames_a = frames_b = None
    return PhantomCase(
        preset=preset,
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
    )


def _preset_key(preset: str) -> int:
    return sum((k + 1) * ord(c) for k, c in enumerate(preset))

