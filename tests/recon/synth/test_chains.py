"""Imaging chains: every chain renders, each mapping is what it says (recon/synth/chains.py)."""

from dataclasses import replace

import numpy as np
import pytest

from recon.geometry import ViewGeometry
from recon.synth import ALL_CHAINS, CHAINS, make_phantom
from recon.synth.anatomy import Catheter
from recon.synth.chain_render import render_chain_view, supersample_for
from recon.synth.chains import ChainDraw, display_values, draw_chain


def small_draw(name: str, size: int = 96, spacing: float = 0.3) -> ChainDraw:
    draw = draw_chain(ALL_CHAINS[name], np.random.default_rng(3))
    return replace(draw, rows=size, cols=size, pixel_spacing_mm=spacing)


def small_view(draw: ChainDraw) -> ViewGeometry:
    sp = draw.pixel_spacing_mm
    return ViewGeometry(0.0, 0.0, 1000.0, 750.0, (sp, sp), draw.rows, draw.cols)


def straight(p0, p1, radius, step=0.1):
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    n = int(round(np.linalg.norm(p1 - p0) / step)) + 1
    t = np.linspace(0.0, 1.0, n)
    return p0 + t[:, None] * (p1 - p0), np.full(n, radius)


def test_there_are_at_least_six_chains_spanning_the_ranges():
    chains = list(CHAINS.values())
    assert len(chains) >= 6
    assert {c.mapping for c in chains} == {"lin", "log", "disp"}
    assert {c.bits_stored for c in chains} == {8, 12}
    assert {c.size_px for c in chains} == {512, 1024}
    assert {c.tag for c in chains} == {"LIN", "LOG", "DISP", None}
    assert min(c.blur_px[0] for c in chains) <= 0.5 and max(c.blur_px[1] for c in chains) >= 1.5
    assert min(c.scatter_fraction[0] for c in chains) == 0.0
    assert max(c.scatter_fraction[1] for c in chains) >= 0.3
    assert min(c.noise_factor[0] for c in chains) <= 0.5
    assert max(c.noise_factor[1] for c in chains) >= 3.0
    assert {b for c in chains for b in c.background} == {"ribs", "diaphragm", "catheter", "table"}
    fine = [c for c in chains if c.size_px == 1024]
    assert fine and all(0.154 <= c.pixel_spacing_mm[0] and c.pixel_spacing_mm[1] <= 0.2
                        for c in fine)


def test_draws_stay_inside_the_chain_ranges_and_are_seeded():
    for chain in ALL_CHAINS.values():
        for seed in range(5):
            d = draw_chain(chain, np.random.default_rng(seed))
            assert chain.pixel_spacing_mm[0] <= d.pixel_spacing_mm <= chain.pixel_spacing_mm[1]
            assert chain.blur_px[0] <= d.blur_px <= chain.blur_px[1]
            assert chain.scatter_fraction[0] <= d.scatter_fraction <= chain.scatter_fraction[1]
            assert chain.noise_factor[0] <= d.noise_factor <= chain.noise_factor[1]
            assert d == draw_chain(chain, np.random.default_rng(seed))


@pytest.mark.parametrize("name", list(ALL_CHAINS))
def test_every_chain_renders_a_vessel_and_a_catheter(name):
    draw = small_draw(name)
    view = small_view(draw)
    vessel = straight([-8.0, 0.0, -4.0], [8.0, 0.0, -4.0], 1.5)
    z = np.arange(0.0, 40.0, 0.1)  # the catheter runs from inside the field out of it
    cath_X = np.column_stack([np.full(len(z), 5.0), np.full(len(z), 8.0), z])
    catheter = Catheter(cath_X, 6, 1.0, 0.89)
    img = render_chain_view(np.random.default_rng(0), view, [vessel], draw, catheter=catheter)
    assert img.shape == (draw.rows, draw.cols) and img.dtype == np.float32
    assert np.all(img == np.round(img)) and img.min() >= 0 and img.max() <= draw.max_value
    px_per_mm = 1.0 / draw.pixel_spacing_mm

    def at(p):
        return img[np.round(p[:, 1]).astype(int), np.round(p[:, 0]).astype(int)]

    # Vessels are dark (MONOCHROME2): along the vessel's projection against 4 mm aside.
    on = view.project(vessel[0][20:-20:10])
    assert np.median(at(on)) < np.median(at(on + [0.0, 4.0 * px_per_mm]))
    c_on = view.project(cath_X[5:80:5])  # z 0.5-8 mm: inside the field
    c_off = c_on - [4.0 * px_per_mm, 0.0]
    if "catheter" in draw.background:
        assert np.median(at(c_on)) < np.median(at(c_off))


def test_the_lin_mapping_is_affine_in_intensity():
    draw = small_draw("ii-12bit-lin")
    t = np.linspace(0.05, 1.2, 200)[None, :]
    v = display_values(t, draw)
    expected = draw.max_value * (draw.dark + draw.level * t)
    assert np.max(np.abs(v - expected)) <= 0.5 + 1e-9


def test_the_log_mapping_is_affine_in_the_line_integral():
    draw = small_draw("flat-1024-log")
    L = np.linspace(0.0, 2.0, 300)[None, :]  # line integral of mu
    v = display_values(np.exp(-L), draw)
    expected = draw.max_value * (draw.log_offset - draw.log_gain * L)
    assert np.max(np.abs(v - expected)) <= 0.5 + 1e-6  # affine in L, to the rounding


def test_the_display_mapping_enhances_edges():
    draw = replace(small_draw("sharp-display"), unsharp_gain=1.5)
    t = np.ones((64, 64))
    t[:, 32:] = 0.6  # an edge: darker on the right
    v = display_values(t, draw)
    plain = display_values(t, replace(draw, unsharp_gain=0.0))
    row = v[32]
    assert row[28:32].max() > plain[32, 28:32].max()  # overshoot on the bright side
    assert row[32:36].min() < plain[32, 32:36].min()  # undershoot on the dark side
    assert row[0] == plain[32, 0]  # far from the edge: the gamma curve alone


def test_eight_bit_chains_store_integers_0_to_255():
    case = make_phantom("static", 2, chain="glare-8bit")
    for img in (case.image_a, case.image_b):
        assert img.min() >= 0 and img.max() <= 255
        assert np.all(img == np.round(img))
        assert img.max() > 100
    assert case.chain.bits_stored == 8 and case.chain.tag is None


def test_a_1024_chain_changes_the_detector_and_keeps_the_field_fractions():
    case = make_phantom("data2", 4, chain="flat-1024-log", render=False)
    d = case.chain
    for view in (case.view_a, case.view_b_nominal, case.view_b_true):
        assert (view.rows, view.cols) == (1024, 1024)
        assert view.pixel_spacing_mm == (d.pixel_spacing_mm, d.pixel_spacing_mm)
        p = view.project(case.truth.segment_X_world)
        assert p.min() >= 1024 * 20 / 512 and p.max() <= 1024 * 490 / 512
    assert case.catheter is not None and case.catheter.french in (6, 7)
    assert case.catheter.outer_radius_mm == pytest.approx(case.catheter.french / 6.0)
    assert supersample_for(d.pixel_spacing_mm) == 1
    assert supersample_for(0.39) == 2


def test_the_catheter_leaves_the_field_and_starts_at_the_ostium():
    case = make_phantom("data1", 6, chain="ii-12bit-lin", render=False)
    cath = case.catheter
    ostium = case.truth.vessels[0][0][0]
    assert np.linalg.norm(cath.X_world[0] - ostium) == pytest.approx(0.5, abs=1e-6)
    for view in (case.view_a, case.view_b_true):
        c, r = view.project(cath.X_world[-1:])[0]
        assert not (0 <= c < view.cols and 0 <= r < view.rows)


def test_chain_cases_are_deterministic_and_reject_cine():
    a = make_phantom("static", 9, chain="low-dose-log")
    b = make_phantom("static", 9, chain="low-dose-log")
    assert np.array_equal(a.image_a, b.image_a) and a.seeds == b.seeds
    with pytest.raises(ValueError, match="one frame"):
        make_phantom("static", 9, chain="low-dose-log", n_frames=3)
    with pytest.raises(ValueError, match="unknown imaging chain"):
        make_phantom("static", 9, chain="nope")


def test_a_chain_case_is_written_with_its_tag_and_bits(tmp_path):
    import json

    from recon.io import load_angiogram
    from recon.io.phantom_case import write_phantom_case

    case = make_phantom("static", 2, chain="flat-1024-disp-8bit", anatomy="loop")
    paths = write_phantom_case(case, tmp_path)
    angio = load_angiogram(paths["a"])
    assert angio.info["bits_stored"] == 8
    assert angio.info.get("pixel_intensity_relationship") == "DISP"
    assert np.array_equal(angio.image, case.image_a)
    truth = json.loads(paths["truth"].read_text())
    assert truth["chain"]["name"] == "flat-1024-disp-8bit"
    assert truth["anatomy"]["name"] == "loop"
