"""The clinical export chain (issue 45): JPEG, a faint view beside a catheter and a lead,
a table shift; and the six older chains' cases unchanged (recon/synth)."""

import hashlib
import io

import numpy as np
import pytest
from PIL import Image
from scipy import ndimage

from recon.geometry import ViewGeometry
from recon.synth import ALL_CHAINS, CHAINS, VARIED_CHAINS, make_phantom, varied_cases
from recon.synth.anatomy import LEAD_OFFSET_MM, pacing_lead
from recon.synth.chain_render import render_chain_view
from recon.synth.chains import CLINICAL_CHAINS, draw_chain, jpeg_roundtrip
from recon.synth.clicks import random_header_error
from recon.synth.presets import preset_view
from recon.synth.suites import CASE_SEED_STRIDE, make_suite_case

NEW = "clinical-jpeg-8bit"


def short_hash(a) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()[:16]


#: sha256 (first 16 hex) of image_a, image_b, the truth's segment_X_world and view B's
#: true translation, computed with the code BEFORE the clinical chain existed (main
#: 6506f2a), for two cases of varied_cases(2, seed=0).
BEFORE = {
    ("glare-8bit", 301): ("b909567c606c2cda", "d2fc6cbe3fd2a690", "5b6f1f020426cd0b",
                          "38b04d5347874b07"),
    ("sharp-display", 500): ("3056d4992f0fea37", "1ff55aeb893e6724", "546144c923030c8b",
                             "f8f06fb5ecc972a7"),
}


@pytest.mark.parametrize(("chain", "seed"), sorted(BEFORE))
def test_the_older_chains_cases_are_bit_identical_to_before(chain, seed):
    spec = next(c for c in varied_cases(2, 0) if c.chain == chain and c.seed == seed)
    case = make_suite_case(spec)
    got = (short_hash(case.image_a), short_hash(case.image_b),
           short_hash(case.truth.segment_X_world),
           short_hash(np.asarray(case.view_b_true.t_corr_mm)))
    assert got == BEFORE[(chain, seed)]
    assert case.lead is None and "faint_view" not in case.anatomy_info
    assert set(case.chain.to_dict()).isdisjoint({"jpeg_quality", "faint_view"})


def test_the_new_chain_is_appended_last_with_its_own_seeds():
    assert VARIED_CHAINS[:6] == tuple(CHAINS) and VARIED_CHAINS[6:] == (NEW,)
    assert set(ALL_CHAINS) == set(VARIED_CHAINS) and NEW not in CHAINS  # tree-varied: six
    for seed in (0, 2000, 6100):
        cases = varied_cases(8, seed)
        old = [c for c in cases if c.chain != NEW]
        assert cases[: len(old)] == old  # the six chains' cases come first, as before
        new = [c for c in cases if c.chain == NEW]
        assert [c.seed for c in new] == [seed + 6 * CASE_SEED_STRIDE + k for k in range(8)]
        assert len({c.seed for c in cases}) == len(cases)
        # the older chains' seeds stop below seed + 600: no case shares a seed with chain 6
        assert max(c.seed for c in old) < min(c.seed for c in new)


def test_jpeg_roundtrip_is_lossy_with_8x8_blocks():
    rng = np.random.default_rng(4)
    yy, xx = np.mgrid[0:128, 0:128]
    img = np.clip(np.round(120 + 0.4 * xx + 30 * np.sin(yy / 9.0) + rng.normal(0, 4, xx.shape)),
                  0, 255)
    out = jpeg_roundtrip(img, 75)
    assert out.dtype == np.float32 and out.shape == img.shape
    assert np.all(out == np.round(out)) and out.min() >= 0 and out.max() <= 255
    err = np.abs(out - img)
    assert 0.5 < err.mean() < 4.0  # lossy, but close
    # Block artefacts: the step across a block edge (column 8k-1 -> 8k) is larger than
    # the step inside a block, in the JPEG image and not in the original.
    def edge_ratio(a):
        d = np.abs(np.diff(a, axis=1))
        return d[:, 7::8].mean() / d[:, 3::8].mean()
    assert edge_ratio(out) > 1.15 * edge_ratio(img)
    assert np.array_equal(jpeg_roundtrip(img, 75), out)  # deterministic
    for q in (75, 92):  # the same JPEG as Pillow's baseline encoder and decoder give
        buf = io.BytesIO()
        Image.fromarray(img.astype(np.uint8)).save(buf, format="JPEG", quality=q)
        buf.seek(0)
        assert np.array_equal(jpeg_roundtrip(img, q), np.asarray(Image.open(buf), dtype=np.float32))
    with pytest.raises(ValueError, match="8-bit"):
        jpeg_roundtrip(img * 4, 75)


def test_the_clinical_draw_has_its_quality_faint_view_and_window():
    chain = CLINICAL_CHAINS[NEW]
    for s in range(8):
        d = draw_chain(chain, np.random.default_rng(s))
        assert chain.jpeg_quality[0] <= d.jpeg_quality <= chain.jpeg_quality[1]
        assert d.faint_view in ("A", "B") and 5.0 <= d.faint_contrast_levels <= 10.0
        lo, hi = np.exp(d.window)
        assert 0.3 <= lo <= 0.5 and 1.6 <= hi <= 2.2
        assert d.bits_stored == 8 and d.rows == d.cols == 512 and d.tag is None
    # the first draws are the ones every chain takes: same rng, same detector values
    plain = draw_chain(CHAINS["glare-8bit"], np.random.default_rng(3))
    clin = draw_chain(chain, np.random.default_rng(3))
    assert (plain.scatter_sigma_mm, plain.gamma) == (clin.scatter_sigma_mm, clin.gamma)


def test_the_table_shift_is_10_to_15_mm_in_the_table_plane():
    ap = preset_view(0.0, 0.0, 1000.0, 750.0)  # central ray along world y
    d = ap.nominal_axes[2]
    assert abs(abs(d[1]) - 1.0) < 1e-9
    for s in range(20):
        rot, t = random_header_error(np.random.default_rng(s), ap, shift_mm=(10.0, 15.0),
                                     in_table_plane=True)
        rot0, t0 = random_header_error(np.random.default_rng(s), ap)
        assert np.array_equal(rot, rot0)  # the same draws
        assert 5.0 - 1e-9 <= abs(t[1]) <= 15.0 + 1e-9  # along the ray: the SOD error alone
        assert 10.0 - 1e-9 <= np.hypot(t[0], t[2]) <= 15.0 + 1e-9  # x, z: the table plane
        assert np.hypot(t0[0], t0[2]) <= 5.0 + 1e-9  # the older chains: 2-5 mm


def test_the_lead_passes_beside_the_segment_and_crosses_both_views():
    case = make_phantom("data1", 11, chain=NEW, render=False)
    lead, seg = case.lead, case.truth.segment_X_world
    assert lead is not None and 0.15 <= lead.radius_mm <= 0.3
    gap = np.min(np.linalg.norm(lead.X_world[:, None, :] - seg[None, ::5, :], axis=2))
    assert gap <= LEAD_OFFSET_MM[1] + 0.5
    for view in (case.view_a, case.view_b_true):
        p = view.project(lead.X_world)
        inside = (p[:, 0] >= 0) & (p[:, 0] < view.cols) & (p[:, 1] >= 0) & (p[:, 1] < view.rows)
        steps = np.linalg.norm(np.diff(p, axis=0), axis=1)[inside[1:] & inside[:-1]]
        assert steps.sum() >= 0.5 * view.cols
    again = pacing_lead(np.random.default_rng(1), seg, (case.view_a, case.view_b_true))
    assert np.array_equal(again.X_world,
                          pacing_lead(np.random.default_rng(1), seg,
                                      (case.view_a, case.view_b_true)).X_world)
    assert case.anatomy_info["faint_view"] == case.chain.faint_view


def _small_scene(contrast_levels):
    chain = CLINICAL_CHAINS[NEW]
    draw = draw_chain(chain, np.random.default_rng(5))
    from dataclasses import replace

    draw = replace(draw, rows=160, cols=160, pixel_spacing_mm=0.3, noise_factor=1.0)
    view = ViewGeometry(0.0, 0.0, 1000.0, 750.0, (0.3, 0.3), 160, 160)
    n = 241
    x = np.linspace(-12.0, 12.0, n)
    vessel = (np.column_stack([x, np.zeros(n), np.full(n, -4.0)]), np.full(n, 1.4))
    kwargs = {}
    if contrast_levels is not None:
        kwargs = {"contrast_levels": contrast_levels, "contrast_X_world": vessel[0]}
    img = render_chain_view(np.random.default_rng(9), view, [vessel], draw, **kwargs)
    return img, view, vessel


def _measured_contrast(img, empty, view, vessel):
    """Median along the vessel of (image without it - image with it), 3 x 3 means."""
    p = view.project(vessel[0][30:-30])
    diff = ndimage.uniform_filter(empty.astype(float) - img.astype(float), 3)
    return float(np.median(ndimage.map_coordinates(diff, p[:, ::-1].T, order=1)))


@pytest.mark.parametrize("levels", [5.0, 9.0])
def test_the_faint_view_puts_the_vessel_a_few_grey_levels_below_its_background(levels):
    img, view, vessel = _small_scene(levels)
    plain, _, _ = _small_scene(None)
    empty, _, _ = _small_scene(0.01)  # the same scene, the vessel's iodine scaled to ~0
    faint_c = _measured_contrast(img, empty, view, vessel)
    assert _measured_contrast(plain, empty, view, vessel) > 25.0  # at full iodine: plain
    assert levels - 1.5 <= faint_c <= levels + 1.5  # noise and JPEG on top of the target
    assert img.max() <= 255 and np.all(img == np.round(img))


def test_a_clinical_case_renders_a_faint_view_and_a_darker_lead():
    case = make_phantom("static", 3, chain=NEW)
    faint = case.anatomy_info["faint_view"]
    views = {"A": (case.image_a, case.view_a), "B": (case.image_b, case.view_b_true)}
    for key, (img, view) in views.items():
        assert img.max() <= 255 and np.all(img == np.round(img))
        assert np.percentile(img, 99) < 255  # the window leaves the field unclipped
        lead_px = view.project(case.lead.X_world)
        inside = ((lead_px[:, 0] > 30) & (lead_px[:, 0] < view.cols - 30) & (lead_px[:, 1] > 30)
                  & (lead_px[:, 1] < view.rows - 30))
        on_lead = ndimage.map_coordinates(img, lead_px[inside][:, ::-1].T, order=1)
        seg = view.project(case.truth.segment_X_world)
        on_vessel = ndimage.map_coordinates(img, seg[:, ::-1].T, order=1)
        # the lead is much darker than the vessel, the more so in the faint view
        assert np.median(on_lead) < np.median(on_vessel) - (20 if key == faint else 0)
