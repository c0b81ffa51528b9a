"""Imaging chains: how an X-ray system turns the line integrals into stored pixel values.

An :class:`ImagingChain` is a named family of X-ray systems: detector size
and pixel spacing, detector blur, scatter / veiling glare, dose (noise),
the background structures in the field, the display mapping of the stored
values and their bit depth, and the PixelIntensityRelationship (0028,1040)
tag a file of it would carry. Each case draws one concrete
:class:`ChainDraw` inside the chain's ranges (:func:`draw_chain`, seeded),
and :func:`recon.synth.chain_render.render_chain_view` renders with it.

Display mappings (DICOM PS3.3, X-Ray Image module, Pixel Intensity
Relationship (0028,1040): LIN, LOG, DISP):

- ``lin``: stored values are affine in the X-ray intensity (the detector
  signal): ``v = max (dark + level t)`` with ``t`` = counts / unattenuated
  counts;
- ``log``: stored values are affine in the attenuation (the line integral):
  ``v = max (offset + gain ln t)``, so ``v = max offset - max gain L``;
- ``disp``: display-processed, as in many real XA files: a log transform,
  a window, a gamma curve, then an unsharp mask (edge enhancement)
  ``y + a (y - G_sigma y)``.

Physical figures:

- Scatter and veiling glare: both add a heavily blurred copy of the primary
  image (scatter: the primary convolved with a broad scatter spread
  function, IAEA, *Diagnostic Radiology Physics: A Handbook for Teachers
  and Students*, 2014, sec. 6.3; veiling glare of image intensifiers: a
  long-tailed PSF, Seibert, Nalcioglu & Roeck, Med. Phys. 11 (1984) 172).
  ``scatter_fraction`` is S / (S + P) in a uniform field; the span 0-30 %
  (clean flat panel to an image intensifier with strong glare) is this
  benchmark's design choice, not a measured distribution.
- Noise: Poisson quanta; at the noise factor 1 a pixel of 0.390625 mm gets
  :data:`recon.synth.render.PHOTONS_PER_PIXEL` quanta, a pixel of another
  size in proportion to its area (the same dose), and a noise factor m
  divides the quanta by m^2 (the relative noise is m times larger).
- Guiding catheter: 6-7 F (1 F = 1/3 mm), :mod:`recon.synth.anatomy`.

The clinical export chain (:data:`CLINICAL_CHAINS`) adds what real pairs
exported from a cath lab show (issue 45): the stored 8-bit values go
through a real baseline JPEG encode and decode (libjpeg through OpenCV,
quality 75-92, :func:`jpeg_roundtrip`); in one view, drawn per case, the vessels
are only 5-10 grey levels below their background (the noise-free contrast
on the stored scale, median along the clicked segment, beside the guiding
catheter and a pacing lead, ``lead`` background,
:func:`recon.synth.anatomy.pacing_lead`); and view B's header misses a
table move of 10-15 mm (the isocentre shift of
:func:`recon.synth.clicks.random_header_error`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

__all__ = [
    "ImagingChain",
    "ChainDraw",
    "CHAINS",
    "CLINICAL_CHAINS",
    "ALL_CHAINS",
    "VARIED_CHAINS",
    "BACKGROUNDS",
    "draw_chain",
    "resolve_chain",
    "display_values",
    "jpeg_roundtrip",
    "MAPPINGS",
]

FloatArray = NDArray[np.float64]

MAPPINGS = ("lin", "log", "disp")
BACKGROUNDS = ("diaphragm", "ribs", "catheter", "table", "lead")
T_MIN = 1e-3  # smallest relative intensity a log mapping takes (collimator leakage is 1e-2)


@dataclass(frozen=True)
class ImagingChain:
    """A named family of X-ray imaging chains; every range is (low, high), drawn uniformly.

    Attributes
    ----------
    name : the chain's key in :data:`CHAINS`.
    mapping : "lin", "log" or "disp" (module docstring).
    size_px : rows = cols of the detector (512 or 1024).
    pixel_spacing_mm : detector pixel size range, mm.
    blur_px : Gaussian detector blur sigma range, px.
    scatter_fraction : scatter + veiling glare range, S / (S + P).
    noise_factor : quantum noise range relative to the plain phantom's (x0.5-x3).
    background : structures in the field, a subset of :data:`BACKGROUNDS`.
    bits_stored : 8 or 12.
    tag : PixelIntensityRelationship (0028,1040) of a file: "LIN", "LOG", "DISP" or None.
    unsharp_gain : edge-enhancement gain range ("disp" only).
    description : one line.
    jpeg_quality : JPEG quality range (integers) of a lossy 8-bit export, or None.
    faint_contrast_levels : grey-level range of the vessels' contrast in the faint
        view (one view per case), or None (no faint view).
    table_shift_mm : range of the table / isocentre shift in view B's header error,
        or None (:data:`recon.synth.clicks.HEADER_SHIFT_MM`).
    window_t : "disp": ranges of the relative intensities t mapped to 0 and to 1,
        or None (0.15-0.3 and 1.1-1.3).
    """

    name: str
    mapping: str
    size_px: int
    pixel_spacing_mm: tuple[float, float]
    blur_px: tuple[float, float]
    scatter_fraction: tuple[float, float]
    noise_factor: tuple[float, float]
    background: tuple[str, ...]
    bits_stored: int
    tag: str | None
    unsharp_gain: tuple[float, float] = (0.0, 0.0)
    description: str = ""
    jpeg_quality: tuple[int, int] | None = None
    faint_contrast_levels: tuple[float, float] | None = None
    table_shift_mm: tuple[float, float] | None = None
    window_t: tuple[tuple[float, float], tuple[float, float]] | None = None

    def __post_init__(self) -> None:
        if self.mapping not in MAPPINGS:
            raise ValueError(f"chain {self.name}: mapping must be one of {MAPPINGS}")
        if self.bits_stored not in (8, 12):
            raise ValueError(f"chain {self.name}: bits_stored must be 8 or 12")
        unknown = set(self.background) - set(BACKGROUNDS)
        if unknown:
            raise ValueError(f"chain {self.name}: unknown background {sorted(unknown)}")
        if self.jpeg_quality is not None and self.bits_stored != 8:
            raise ValueError(f"chain {self.name}: a JPEG export stores 8 bits")


CHAINS: dict[str, ImagingChain] = {
    c.name: c
    for c in (
        ImagingChain(
            "ii-12bit-lin", "lin", 512, (0.30, 0.40), (0.8, 1.2), (0.05, 0.15), (0.8, 1.2),
            ("diaphragm", "ribs", "catheter"), 12, "LIN",
            description="image intensifier, 12-bit values linear in intensity, some glare",
        ),
        ImagingChain(
            "flat-1024-log", "log", 1024, (0.154, 0.20), (0.5, 0.8), (0.0, 0.10), (0.8, 1.5),
            ("diaphragm", "ribs", "catheter", "table"), 12, "LOG",
            description="flat panel 1024 x 1024, fine pixels, 12-bit values linear in attenuation",
        ),
        ImagingChain(
            "flat-1024-disp-8bit", "disp", 1024, (0.154, 0.20), (0.6, 1.0), (0.05, 0.15),
            (1.0, 2.0), ("ribs", "catheter", "table"), 8, "DISP", unsharp_gain=(0.5, 1.0),
            description="flat panel 1024 x 1024, display-processed 8-bit export",
        ),
        ImagingChain(
            "glare-8bit", "lin", 512, (0.30, 0.40), (1.0, 1.5), (0.20, 0.30), (0.8, 1.2),
            ("diaphragm", "catheter"), 8, None,
            description="image intensifier with strong veiling glare, blurred, 8-bit, no tag",
        ),
        ImagingChain(
            "low-dose-log", "log", 512, (0.30, 0.40), (0.6, 1.0), (0.05, 0.15), (2.0, 3.0),
            ("diaphragm", "ribs", "catheter", "table"), 12, None,
            description="low dose (noise x2-x3), values linear in attenuation, no tag",
        ),
        ImagingChain(
            "sharp-display", "disp", 512, (0.35, 0.40), (0.5, 0.7), (0.0, 0.05), (0.5, 0.8),
            ("diaphragm", "ribs", "table"), 12, "DISP", unsharp_gain=(1.0, 2.0),
            description="sharp detector, strong edge enhancement, 12-bit display values",
        ),
    )
}
"""The six synthetic chains (the tree-varied suite cycles these, in this order)."""

CLINICAL_CHAINS: dict[str, ImagingChain] = {
    c.name: c
    for c in (
        ImagingChain(
            "clinical-jpeg-8bit", "disp", 512, (0.28, 0.38), (0.7, 1.1), (0.05, 0.20),
            (1.0, 1.8), ("diaphragm", "ribs", "catheter", "table", "lead"), 8, None,
            unsharp_gain=(0.3, 0.8), jpeg_quality=(75, 92), faint_contrast_levels=(5.0, 10.0),
            table_shift_mm=(10.0, 15.0), window_t=((0.3, 0.5), (1.6, 2.2)),
            description="cath-lab JPEG export (8-bit, baseline JPEG q 75-92): one view's "
            "vessels 5-10 grey levels faint beside the catheter and a pacing lead, "
            "10-15 mm table shift",
        ),
    )
}
"""Chains modelled on real clinical pairs (issue 45), after the six of :data:`CHAINS`."""

ALL_CHAINS: dict[str, ImagingChain] = {**CHAINS, **CLINICAL_CHAINS}
#: The varied suite's chains, in order: the six of CHAINS, then the clinical ones
#: (appended, so the six keep their chain index and case seeds).
VARIED_CHAINS: tuple[str, ...] = tuple(ALL_CHAINS)


@dataclass(frozen=True)
class ChainDraw:
    """One concrete imaging chain of a case: the values drawn inside an :class:`ImagingChain`.

    Attributes
    ----------
    name, mapping, bits_stored, tag, background : as the chain.
    rows, cols : detector size, px.
    pixel_spacing_mm : square detector pixel, mm.
    blur_px : Gaussian detector blur sigma, px.
    scatter_fraction : S / (S + P) in a uniform field.
    scatter_sigma_mm : width (Gaussian sigma, mm at the detector) of the scatter / glare kernel.
    noise_factor : relative quantum noise (1 = the plain phantom's at 0.390625 mm).
    level, dark : "lin": ``v / max = dark + level t``.
    log_offset, log_gain : "log": ``v / max = log_offset + log_gain ln t``.
    window : "disp": (ln t mapped to 0, ln t mapped to 1).
    gamma : "disp": exponent of the windowed value.
    unsharp_gain, unsharp_sigma_mm : "disp": edge enhancement ``y + gain (y - G y)``.
    jpeg_quality : quality of the JPEG export the stored values pass through, or None.
    faint_view : "A" or "B", the view whose vessels are faint, or None.
    faint_contrast_levels : the faint view's vessel contrast, grey levels, or None.
    """

    name: str
    mapping: str
    rows: int
    cols: int
    pixel_spacing_mm: float
    blur_px: float
    scatter_fraction: float
    scatter_sigma_mm: float
    noise_factor: float
    bits_stored: int
    tag: str | None
    background: tuple[str, ...]
    level: float = 0.635
    dark: float = 0.0
    log_offset: float = 0.85
    log_gain: float = 0.3
    window: tuple[float, float] = (float(np.log(0.2)), float(np.log(1.2)))
    gamma: float = 1.0
    unsharp_gain: float = 0.0
    unsharp_sigma_mm: float = 1.5
    jpeg_quality: int | None = None
    faint_view: str | None = None
    faint_contrast_levels: float | None = None

    @property
    def max_value(self) -> int:
        """Largest stored value, 2^bits - 1."""
        return (1 << self.bits_stored) - 1

    def to_dict(self) -> dict:
        """JSON-ready parameters (the clinical export's only when the chain has them)."""
        out = {k: getattr(self, k) for k in self.__dataclass_fields__
               if k not in _CLINICAL_FIELDS or getattr(self, k) is not None}
        out["background"] = list(self.background)
        out["window"] = list(self.window)
        return out


_CLINICAL_FIELDS = ("jpeg_quality", "faint_view", "faint_contrast_levels")


def resolve_chain(chain: str | ImagingChain) -> ImagingChain:
    """The :class:`ImagingChain` of a name; ValueError for an unknown name."""
    if isinstance(chain, ImagingChain):
        return chain
    if chain not in ALL_CHAINS:
        raise ValueError(f"unknown imaging chain {chain!r} (use one of {', '.join(ALL_CHAINS)})")
    return ALL_CHAINS[chain]


def draw_chain(chain: ImagingChain, rng: np.random.Generator) -> ChainDraw:
    """One :class:`ChainDraw` inside ``chain``'s ranges.

    Every chain takes the same draws first; a chain with a JPEG export or a
    faint view takes its further draws after them, so the six chains of
    :data:`CHAINS` draw exactly what they drew before those options existed.
    """
    u = rng.uniform
    spacing = float(u(*chain.pixel_spacing_mm))
    values = {
        "blur_px": float(u(*chain.blur_px)),
        "scatter_fraction": float(u(*chain.scatter_fraction)),
        "scatter_sigma_mm": float(u(15.0, 40.0)),
        "noise_factor": float(u(*chain.noise_factor)),
        "level": float(u(0.45, 0.7)),
        "dark": float(u(0.0, 0.03)),
        "log_offset": float(u(0.75, 0.9)),
        "log_gain": float(u(0.25, 0.4)),
        "window": (float(np.log(u(0.15, 0.3))), float(np.log(u(1.1, 1.3)))),
        "gamma": float(u(0.7, 1.4)),
        "unsharp_gain": float(u(*chain.unsharp_gain)),
        "unsharp_sigma_mm": float(u(0.8, 2.5)),
    }
    if chain.jpeg_quality is not None:
        values["jpeg_quality"] = int(rng.integers(chain.jpeg_quality[0], chain.jpeg_quality[1] + 1))
    if chain.faint_contrast_levels is not None:
        values["faint_view"] = "AB"[int(rng.integers(2))]
        values["faint_contrast_levels"] = float(u(*chain.faint_contrast_levels))
    if chain.window_t is not None:
        values["window"] = (float(np.log(u(*chain.window_t[0]))),
                            float(np.log(u(*chain.window_t[1]))))
    return ChainDraw(
        name=chain.name,
        mapping=chain.mapping,
        rows=chain.size_px,
        cols=chain.size_px,
        pixel_spacing_mm=spacing,
        bits_stored=chain.bits_stored,
        tag=chain.tag,
        background=chain.background,
        **values,
    )


def display_values(t: ArrayLike, draw: ChainDraw, *, exact: bool = False) -> NDArray:
    """Stored values (H, W) of relative intensities ``t`` (H, W) under the chain's mapping.

    ``t`` is counts / unattenuated counts (1 = no attenuation; scatter can
    take it above 1). Values are rounded and clipped to 0..2^bits - 1
    (integers stored as float32); ``exact``: clipped but not rounded
    (float64, for measuring a contrast below one grey level's precision).
    """
    t = np.asarray(t, dtype=float)
    top = float(draw.max_value)
    if draw.mapping == "lin":
        y = draw.dark + draw.level * t
    elif draw.mapping == "log":
        y = draw.log_offset + draw.log_gain * np.log(np.maximum(t, T_MIN))
    else:
        lo, hi = draw.window
        y = np.clip((np.log(np.maximum(t, T_MIN)) - lo) / (hi - lo), 0.0, 1.0) ** draw.gamma
        if draw.unsharp_gain > 0:
            sigma_px = draw.unsharp_sigma_mm / draw.pixel_spacing_mm
            y = y + draw.unsharp_gain * (y - ndimage.gaussian_filter(y, sigma_px, mode="nearest"))
    if exact:
        return np.clip(y * top, 0.0, top)
    return np.clip(np.round(y * top), 0.0, top).astype(np.float32)


def jpeg_roundtrip(values: ArrayLike, quality: int) -> NDArray[np.float32]:
    """8-bit stored values (H, W) after a baseline JPEG encode and decode at ``quality``.

    A real lossy export, in memory: OpenCV's libjpeg encoder (greyscale, 8 x
    8 DCT blocks, the IJG quantisation tables scaled to ``quality`` as every
    libjpeg-based exporter scales them, baseline, not progressive, no
    optimised Huffman tables), then its decoder. ``values`` must be
    integers in 0..255.
    """
    img = np.asarray(values)
    if img.ndim != 2 or img.min() < 0 or img.max() > 255:
        raise ValueError("jpeg_roundtrip takes one 8-bit image (H, W) of values 0..255")
    params = [cv2.IMWRITE_JPEG_QUALITY, int(quality), cv2.IMWRITE_JPEG_PROGRESSIVE, 0,
              cv2.IMWRITE_JPEG_OPTIMIZE, 0]
    ok, buf = cv2.imencode(".jpg", np.round(img).astype(np.uint8), params)
    if not ok:
        raise ValueError("the JPEG encoder refused the image")
    return cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE).astype(np.float32)
