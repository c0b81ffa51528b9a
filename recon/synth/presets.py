"""The phantom's C-arm presets: pairs of nominal (header) view geometries.

Every view has the real files' detector: 512 x 512 px of 0.390625 mm
(a 200 mm field).
"""

from __future__ import annotations

from dataclasses import dataclass

from recon.geometry import ViewGeometry

__all__ = ["IMAGE_SIZE_PX", "PIXEL_SPACING_MM", "PhantomPreset", "PRESETS", "preset_view"]

IMAGE_SIZE_PX = 512
PIXEL_SPACING_MM = 0.390625  # 200 mm field on 512 px, as the real files


def preset_view(alpha: float, beta: float, sid: float, sod: float) -> ViewGeometry:
    """A phantom view (no correction): angles in degrees, SID and SOD in mm."""
    return ViewGeometry(
        alpha_deg=alpha,
        beta_deg=beta,
        sid_mm=sid,
        sod_mm=sod,
        pixel_spacing_mm=(PIXEL_SPACING_MM, PIXEL_SPACING_MM),
        rows=IMAGE_SIZE_PX,
        cols=IMAGE_SIZE_PX,
    )


@dataclass(frozen=True)
class PhantomPreset:
    """A pair of nominal header geometries.

    Attributes
    ----------
    name : preset key.
    view_a, view_b : nominal (header) geometries of the two views.
    description : where the numbers come from.
    """

    name: str
    view_a: ViewGeometry
    view_b: ViewGeometry
    description: str


PRESETS: dict[str, PhantomPreset] = {
    "data1": PhantomPreset(
        "data1",
        preset_view(45.5, -28.2, 1200.0, 749.0),
        preset_view(-24.8, -27.0, 1147.0, 844.0),
        "seed paper Table 1, data 1 (LAO 45.5 CAU 28.2 / RAO 24.8 CAU 27)",
    ),
    "data2": PhantomPreset(
        "data2",
        preset_view(45.2, 0.0, 1028.0, 759.4),
        preset_view(0.9, 33.0, 1064.0, 766.4),
        "seed paper Table 1, data 2 (LAO 45.2 / LAO 0.9 CRA 33)",
    ),
    "data3": PhantomPreset(
        "data3",
        preset_view(-21.6, -21.0, 1075.0, 782.7),
        preset_view(44.3, -28.8, 1118.0, 785.0),
        "seed paper Table 1, data 3 (RAO 21.6 CAU 21 / LAO 44.3 CAU 28.8)",
    ),
    "static": PhantomPreset(
        "static",
        preset_view(-29.3, 25.5, 976.0, 720.0),
        preset_view(30.7, 23.6, 976.0, 720.0),
        "like the real static phantom pair IM7/IM8 (RAO 29.3 CRA 25.5 / LAO 30.7 CRA 23.6)",
    ),
}
