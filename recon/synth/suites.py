"""Suites of phantom cases: the varied suite that no single imaging chain can fool.

:func:`varied_cases` lists, for every imaging chain of
:data:`recon.synth.chains.VARIED_CHAINS`, ``n_per_chain`` seeded cases: the
geometry alternates between the paper's Table-1 presets (and the static
pair) and random C-arm pairs (:func:`random_geometry`), and the anatomy
cycles through the plain tree and the harder variants
(:data:`recon.synth.anatomy.ANATOMY_CYCLE`). Each chain starts the cycles
at its own offset, so every chain meets every variant and preset.
:func:`make_suite_case` makes one of them.

The chains, in their order (chain j's cases have seeds ``seed + 100 j + k``):

0. ``ii-12bit-lin``: image intensifier, 12-bit values linear in intensity;
1. ``flat-1024-log``: flat panel 1024 x 1024, 12-bit values linear in attenuation;
2. ``flat-1024-disp-8bit``: display-processed 8-bit export of a flat panel;
3. ``glare-8bit``: strong veiling glare, blurred, 8-bit, no tag;
4. ``low-dose-log``: noise x2-x3, values linear in attenuation, no tag;
5. ``sharp-display``: strong edge enhancement, 12-bit display values;
6. ``clinical-jpeg-8bit`` (added for issue 45, after the real clinical pairs):
   a cath-lab export through a real baseline JPEG (quality 75-92); in one
   view (A or B, drawn) the vessels are 5-10 grey levels below their
   background, beside the guiding catheter and a pacing lead that crosses
   the field 2-6 mm from the clicked segment; view B's header misses a
   10-15 mm table shift.

Chain 6 was appended: chains 0-5 keep their index, seeds, geometries,
anatomy and images (bit-identical to the suite before it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from recon.synth.anatomy import ANATOMY_CYCLE
from recon.synth.case import PhantomCase, make_phantom
from recon.synth.chains import VARIED_CHAINS
from recon.synth.presets import PRESETS, PhantomPreset, preset_view

__all__ = [
    "SuiteCase",
    "varied_cases",
    "random_geometry",
    "make_suite_case",
    "TABLE1_CYCLE",
    "MIN_SEPARATION_DEG",
]

#: The Table-1 presets and the static pair, in the order the suite takes them.
TABLE1_CYCLE = ("data1", "data2", "data3", "static")
MIN_SEPARATION_DEG = 30.0  # least angle between the two views' central rays
MAX_SEPARATION_DEG = 110.0
PRIMARY_DEG = (-60.0, 60.0)  # RAO 60 .. LAO 60
SECONDARY_DEG = (-35.0, 35.0)  # CAU 35 .. CRA 35
SID_MM = (950.0, 1250.0)
SOD_MM = (700.0, 820.0)
CASE_SEED_STRIDE = 100  # chain j's case k has seed seed + 100 j + k


@dataclass(frozen=True)
class SuiteCase:
    """One case of a suite: which chain, geometry, seed and anatomy.

    Attributes
    ----------
    chain : imaging chain name (one of :data:`recon.synth.chains.VARIED_CHAINS`).
    preset : a :data:`recon.synth.presets.PRESETS` key or a random :class:`PhantomPreset`.
    seed : the case's seed.
    anatomy : anatomy variant name (a key of :data:`recon.synth.anatomy.ANATOMIES`).
    """

    chain: str
    preset: str | PhantomPreset
    seed: int
    anatomy: str

    @property
    def preset_name(self) -> str:
        """The preset's name (a random geometry's is "random-<chain index>-<case>")."""
        return self.preset if isinstance(self.preset, str) else self.preset.name

    def to_dict(self) -> dict:
        """JSON-ready description (with the random geometry's angles and distances)."""
        p = PRESETS[self.preset] if isinstance(self.preset, str) else self.preset
        views = {
            k: {"alpha_deg": v.alpha_deg, "beta_deg": v.beta_deg, "sid_mm": v.sid_mm,
                "sod_mm": v.sod_mm}
            for k, v in (("a", p.view_a), ("b", p.view_b))
        }
        return {"chain": self.chain, "preset": self.preset_name, "seed": self.seed,
                "anatomy": self.anatomy, "geometry": views}


def _direction(alpha_deg: float, beta_deg: float) -> np.ndarray:
    a, b = np.deg2rad(alpha_deg), np.deg2rad(beta_deg)
    return np.array([np.sin(a) * np.cos(b), -np.cos(a) * np.cos(b), np.sin(b)])


def random_geometry(rng: np.random.Generator, name: str) -> PhantomPreset:
    """A random pair of C-arm views whose central rays are 30-110 degrees apart.

    Primary angles RAO 60 .. LAO 60, secondary CAU 35 .. CRA 35, SID 950-1250
    mm, SOD 700-820 mm, each view drawn on its own.
    """
    while True:
        angles = rng.uniform(*PRIMARY_DEG, 2), rng.uniform(*SECONDARY_DEG, 2)
        cosine = _direction(angles[0][0], angles[1][0]) @ _direction(angles[0][1], angles[1][1])
        sep = float(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))))
        if MIN_SEPARATION_DEG <= sep <= MAX_SEPARATION_DEG:
            break
    sid, sod = rng.uniform(*SID_MM, 2), rng.uniform(*SOD_MM, 2)
    views = [preset_view(float(angles[0][k]), float(angles[1][k]), float(sid[k]),
                         float(sod[k])) for k in range(2)]
    return PhantomPreset(name, views[0], views[1],
                         f"random pair, central rays {sep:.0f} degrees apart")


def varied_cases(n_per_chain: int = 8, seed: int = 0) -> list[SuiteCase]:
    """The varied suite: ``n_per_chain`` cases for every chain, chain by chain.

    Chain j's case k: seed ``seed + 100 j + k``; geometry a Table-1 preset
    (``TABLE1_CYCLE[(k // 2 + j) % 4]``) for even k, a :func:`random_geometry`
    for odd k; anatomy ``ANATOMY_CYCLE[(k + j) % 6]``.
    """
    if n_per_chain < 1:
        raise ValueError(f"n_per_chain must be at least 1, got {n_per_chain}")
    out = []
    for j, chain in enumerate(VARIED_CHAINS):
        for k in range(n_per_chain):
            case_seed = int(seed) + CASE_SEED_STRIDE * j + k
            if k % 2 == 0:
                preset: str | PhantomPreset = TABLE1_CYCLE[(k // 2 + j) % len(TABLE1_CYCLE)]
            else:
                rng = np.random.default_rng([int(seed), j, k, 17])
                preset = random_geometry(rng, f"random-{j}-{k}")
            anatomy = ANATOMY_CYCLE[(k + j) % len(ANATOMY_CYCLE)]
            out.append(SuiteCase(chain, preset, case_seed, anatomy))
    return out


def make_suite_case(case: SuiteCase, *, stenosis_pct: float = 50.0,
                    render: bool = True) -> PhantomCase:
    """The phantom case of a :class:`SuiteCase`."""
    return make_phantom(case.preset, case.seed, stenosis_pct=stenosis_pct, render=render,
                        chain=case.chain, anatomy=case.anatomy)
