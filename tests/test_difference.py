"""Colour differences against Sharma, Wu & Dalal (2005) and colour-science."""

from __future__ import annotations

import colour
import numpy as np
import pytest

from flakelab.core.difference import DELTA_E_METHODS, delta_E, delta_E_CIE2000, delta_LCH

# Sharma, Wu & Dalal (2005), Table 1: pairs 1, 2, 3, 7, 17, 25, 34.
SHARMA = [
    ((50.0000, 2.6772, -79.7751), (50.0000, 0.0000, -82.7485), 2.0425),
    ((50.0000, 3.1571, -77.2803), (50.0000, 0.0000, -82.7485), 2.8615),
    ((50.0000, 2.8361, -74.0200), (50.0000, 0.0000, -82.7485), 3.4412),
    ((50.0000, 0.0000, 0.0000), (50.0000, -1.0000, 2.0000), 2.3669),
    ((50.0000, 2.5000, 0.0000), (73.0000, 25.0000, -18.0000), 27.1492),
    ((60.2574, -34.0099, 36.2677), (60.4626, -34.1751, 39.4387), 1.2644),
    ((22.7233, 20.0904, -46.6940), (23.0331, 14.9730, -42.5619), 2.0373),
]


@pytest.mark.parametrize(("lab_1", "lab_2", "expected"), SHARMA)
def test_ciede2000_matches_sharma_2005(lab_1, lab_2, expected):
    assert delta_E_CIE2000(lab_1, lab_2) == pytest.approx(expected, abs=5e-5)
    assert delta_E_CIE2000(lab_2, lab_1) == pytest.approx(expected, abs=5e-5)  # symmetric


def test_ciede2000_equals_colour_science_for_kL_1_and_2():
    rng = np.random.default_rng(11)
    a = rng.uniform([0, -90, -90], [100, 90, 90], (2000, 3))
    b = a + rng.normal(0, 4, a.shape)
    np.testing.assert_allclose(delta_E_CIE2000(a, b), colour.difference.delta_E_CIE2000(a, b))
    np.testing.assert_allclose(
        delta_E_CIE2000(a, b, kL=2), colour.difference.delta_E_CIE2000(a, b, textiles=True)
    )


def test_parametric_factor_divides_its_own_term():
    # A pure lightness difference: ΔE00 ∝ 1/kL, independent of kC and kH.
    base = delta_E_CIE2000([50, 10, 10], [52, 10, 10])
    assert delta_E_CIE2000([50, 10, 10], [52, 10, 10], kL=2, kC=3, kH=4) == pytest.approx(base / 2)


@pytest.mark.parametrize("method", ["CIE 1976", "CMC", "DIN99", "CAM16-UCS"])
def test_dispatcher_matches_colour_science(method):
    a, b = np.array([52.0, 20.0, -31.0]), np.array([53.0, 18.5, -30.0])
    got = delta_E(a, b, method=method)
    if method == "CAM16-UCS":
        assert 0.5 < got < 5  # same order as ΔE00 (≈ 1.5) for a small difference
    else:
        assert got == pytest.approx(colour.delta_E(a, b, method=method))
    assert delta_E(a, a, method=method) == pytest.approx(0, abs=1e-9)


def test_dispatcher_rejects_unknown_method_and_option_with_valid_names():
    with pytest.raises(ValueError, match="expected a ΔE method among CIE 2000"):
        delta_E([50, 0, 0], [50, 0, 0], method="CIE 2001")
    with pytest.raises(TypeError, match="CIE 2000 takes options kL, kC, kH; got k_L"):
        delta_E([50, 0, 0], [50, 0, 0], k_L=2)
    assert set(DELTA_E_METHODS) >= {"CIE 2000", "CIE 1976", "CMC", "DIN99", "CAM16-UCS"}


def test_lch_components_add_up_to_delta_E_ab_and_carry_sign():
    rng = np.random.default_rng(5)
    a = rng.uniform([20, -60, -60], [90, 60, 60], (500, 3))
    b = a + rng.normal(0, 3, a.shape)
    d = delta_LCH(a, b)
    np.testing.assert_allclose((d**2).sum(-1), ((a - b) ** 2).sum(-1), rtol=1e-9)
    # a red made yellower turns counter-clockwise: positive ΔH
    assert delta_LCH([50, 40, 0], [50, 40, 5])[2] > 0
    assert delta_LCH([50, 40, 0], [50, 45, 0])[1] == pytest.approx(5)


def _metameric_pair(seed: int = 2):
    """A smooth paint spectrum and its metamer under D65/10: the spectrum plus a 'metameric
    black', a spectral change the D65 weights do not see (Cohen and Kappauf)."""
    from flakelab.core.colorimetry import tristimulus_weights

    wavelengths = np.arange(400, 701, 10)
    standard = 0.3 + 0.2 * np.sin((wavelengths - 400) / 60.0)
    W = tristimulus_weights()  # [31, 3]
    wiggle = 0.05 * np.cos((wavelengths - 400) / 25.0 + seed)
    black = wiggle - W @ np.linalg.solve(W.T @ W, W.T @ wiggle)
    return standard, standard + black


def test_metamerism_index_is_the_corrected_difference_under_the_test_light():
    """ISO 18314-4 by hand, from colour-science's own spectral tristimulus integration (an
    independent path to the XYZ): the sample's XYZ under A scaled by the standard's over the
    sample's under D65, then CIEDE2000 from the standard under A."""
    from flakelab.core.difference import metamerism_index

    standard, sample = _metameric_pair()
    sample = 1.07 * sample + 0.01  # off in strength and tint too
    shape = colour.SpectralShape(400, 700, 10)
    cmfs = colour.MSDS_CMFS["CIE 1964 10 Degree Standard Observer"]

    def XYZ(R, illuminant):
        sd = colour.SpectralDistribution(dict(zip(shape.wavelengths, R, strict=True)))
        return colour.sd_to_XYZ(sd, cmfs, colour.SDS_ILLUMINANTS[illuminant], method="ASTM E308",
                                shape=shape) / 100  # fmt: skip

    corrected = XYZ(sample, "A") * XYZ(standard, "D65") / XYZ(sample, "D65")
    white = colour.XYZ_to_xy(XYZ(np.ones(31), "A"))
    by_hand = colour.difference.delta_E_CIE2000(
        colour.XYZ_to_Lab(XYZ(standard, "A"), white), colour.XYZ_to_Lab(corrected, white)
    )
    assert metamerism_index(standard, sample, "A") == pytest.approx(by_hand, abs=1e-6)


def test_a_metamer_matches_in_daylight_and_its_index_is_its_difference_under_the_test_light():
    from flakelab.core.colorimetry import Conditions, reflectance_to_Lab
    from flakelab.core.difference import METAMERISM_ILLUMINANTS, metamerism_indices

    standard, metamer = _metameric_pair()
    assert delta_E(reflectance_to_Lab(standard), reflectance_to_Lab(metamer)) < 1e-6
    indices = metamerism_indices(np.stack([standard] * 2), np.stack([standard, metamer]))
    assert list(indices) == list(METAMERISM_ILLUMINANTS)
    for test, index in indices.items():
        lab = [reflectance_to_Lab(R, conditions=Conditions(test)) for R in (standard, metamer)]
        # no daylight difference to correct for: the index is the plain ΔE00 under the test light
        assert index[1] == pytest.approx(float(delta_E(*lab)), abs=1e-6)
        assert index[0] == pytest.approx(0.0, abs=1e-9) and index[1] > 0.2
    # strength alone is no metamerism, whatever the light
    assert metamerism_indices(standard, 0.7 * standard)["FL11"] == pytest.approx(0.0, abs=1e-9)


def test_a_sample_reading_black_has_its_plain_difference_as_its_index():
    """A spray-out reading 0 at a geometry (a fuzzed file, stop 66) divided the
    multiplicative correction by zero: a NaN index and colour-science's warning on the
    command line. Its index is now the pair's plain ΔE00 under the test light."""
    import warnings

    from flakelab.core.colorimetry import Conditions, reflectance_to_Lab
    from flakelab.core.difference import metamerism_indices

    standard, _ = _metameric_pair()
    black = np.zeros_like(standard)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        indices = metamerism_indices(np.stack([standard] * 2), np.stack([black, 0.9 * standard]))
    for test, index in indices.items():
        lab = [reflectance_to_Lab(R, conditions=Conditions(test)) for R in (standard, black)]
        assert index[0] == pytest.approx(float(delta_E(*lab)), abs=1e-6) and index[0] > 30
        assert index[1] == pytest.approx(0.0, abs=1e-9)  # the others as before
    # the optimiser's smooth index too: finite, with a finite gradient (the correction of a
    # spray-out black at one geometry came out NaN at every geometry before)
    import torch

    from flakelab.core.torch_colour import TorchMetamerism

    R = torch.tensor(np.stack([black, 0.9 * standard]), requires_grad=True)
    smooth = TorchMetamerism(np.stack([standard] * 2)).indices(R)
    (gradient,) = torch.autograd.grad(smooth.sum(), R)
    assert torch.isfinite(smooth).all() and torch.isfinite(gradient).all()
    assert float(smooth[0].min().detach()) > 30 and float(smooth[1].max().detach()) < 1e-2


def test_the_optimiser_s_metamerism_index_is_iso_18314_4_with_cie94():
    """TorchMetamerism against the correction done by hand on colour-science's XYZ and CIE94
    (graphic arts) from colour-science: the smooth index the search weighs."""
    import torch

    from flakelab.core.colorimetry import (
        Conditions,
        reflectance_to_Lab,
        reflectance_to_XYZ,
        white_point,
    )
    from flakelab.core.difference import METAMERISM_ILLUMINANTS
    from flakelab.core.torch_colour import TorchMetamerism

    standard, metamer = _metameric_pair()
    standards = np.stack([standard, 0.5 * standard + 0.05])  # two geometries
    samples = np.stack([np.stack([metamer, 0.52 * standard + 0.04]), standards])  # two recipes
    smooth = TorchMetamerism(standards).indices(torch.as_tensor(samples)).numpy()
    assert smooth.shape == (2, 2, len(METAMERISM_ILLUMINANTS))  # recipes, geometries, lights
    for k, light in enumerate(METAMERISM_ILLUMINANTS):
        test = Conditions(light)
        white = colour.XYZ_to_xy(white_point(conditions=test))
        corrected = reflectance_to_XYZ(samples, conditions=test) * (
            reflectance_to_XYZ(standards) / reflectance_to_XYZ(samples)
        )
        lab_standard = colour.XYZ_to_Lab(reflectance_to_XYZ(standards, conditions=test), white)
        cie94 = colour.difference.delta_E_CIE1994(lab_standard, colour.XYZ_to_Lab(corrected, white))
        assert smooth[..., k] == pytest.approx(cie94, abs=1e-3)  # the 1e-6 floor under the root
    assert smooth[1].max() < 2e-3  # the standard against itself
    # with the daylight colour from the same product: CIELAB as colour-science has it, and the
    # index under lights of one's choosing the same as under the default set
    lab, by_booth = TorchMetamerism(standards, ("FL2", "A")).lab_and_indices(
        torch.as_tensor(samples)
    )
    assert lab.numpy() == pytest.approx(reflectance_to_Lab(samples), abs=1e-9)
    assert by_booth.numpy()[..., 1] == pytest.approx(smooth[..., 0], abs=1e-12)


def test_test_lights_are_read_as_a_booth_names_them():
    from flakelab.core.difference import parse_lights

    assert parse_lights("A, F2,LED-B3,A") == ("A", "FL2", "LED-B3")
    with pytest.raises(ValueError, match="--lights: .*got 'F99'"):
        parse_lights("A,F99")
    with pytest.raises(ValueError, match="--lights: D65 is the reference illuminant"):
        parse_lights("D65,A")
    with pytest.raises(ValueError, match="--lights: expected test illuminants"):
        parse_lights(" , ")
    for typo in ("-1", "A1", "X11"):  # read as FL1 and FL11 before, silently
        with pytest.raises(ValueError, match=f"--lights: .*got '{typo}'"):
            parse_lights(typo)


def test_the_worst_light_and_the_worst_geometry_per_light_are_read_from_every_geometry():
    from flakelab.core.difference import worst_light, worst_per_light

    indices = {"A": np.array([[0.1, 0.51234], [0.2, 0.3]]), "FL11": np.array([[0.7, 0.1]])}
    assert worst_light(indices) == ("FL11", pytest.approx(0.7))
    assert worst_per_light(indices) == {"A": 0.512, "FL11": 0.7}


def test_a_metamer_is_judged_on_the_unrounded_index():
    # 1.0004 under A: a metamer (over METAMERISM_NOTICE), though the report rounds it to 1.0
    from flakelab.core.difference import METAMERISM_NOTICE, is_metamer, worst_per_light

    indices = {"A": np.array([[0.2, METAMERISM_NOTICE + 4e-4]]), "FL11": np.array([[0.9]])}
    assert is_metamer(indices) and worst_per_light(indices)["A"] == METAMERISM_NOTICE
    assert not is_metamer({"A": np.array([[METAMERISM_NOTICE]]), "FL11": np.array([[0.9]])})
