"""The phantom's C-arm presets (recon/synth/presets.py)."""

from recon.synth.presets import PRESETS


def test_presets_match_table1_and_the_real_pair():
    a, b = PRESETS["data2"].view_a, PRESETS["data2"].view_b
    assert (a.alpha_deg, a.beta_deg, a.sid_mm, a.sod_mm) == (45.2, 0.0, 1028.0, 759.4)
    assert (b.alpha_deg, b.beta_deg, b.sid_mm, b.sod_mm) == (0.9, 33.0, 1064.0, 766.4)
    s = PRESETS["static"]
    assert (s.view_a.alpha_deg, s.view_a.beta_deg, s.view_b.alpha_deg) == (-29.3, 25.5, 30.7)
    for preset in PRESETS.values():
        for view in (preset.view_a, preset.view_b):
            assert (view.rows, view.cols) == (512, 512)
            assert view.pixel_spacing_mm == (0.390625, 0.390625)
