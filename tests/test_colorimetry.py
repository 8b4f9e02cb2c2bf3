"""Colorimetry against the instrument's own numbers and colour-science's direct integration."""

from __future__ import annotations

import colour
import numpy as np
import pytest

from flakelab.core import delta_E_CIE2000
from flakelab.core.colorimetry import (
    D65_10,
    Conditions,
    UnreachableColour,
    reflectance_from_Lab,
    reflectance_to_Lab,
    reflectance_to_sRGB,
    reflectance_to_XYZ,
    white_point,
)
from flakelab.core.spectra import SHAPE_RENDER, WAVELENGTHS, resample
from flakelab.io import read_measurement, read_measurements


def test_lab_from_spectra_equals_instrument_lab_in_every_ma_t12_export(ma_t12_files):
    worst = 0.0
    for path in ma_t12_files:
        m = read_measurement(path)
        assert m.stored_lab is not None and len(m.geometries) == 12
        worst = max(worst, float(delta_E_CIE2000(m.lab(), m.stored_lab).max()))
    assert worst <= 0.01


def test_lab_from_spectra_equals_instrument_lab_for_all_2760_readings(ma_t12_dir):
    measurements = read_measurements(ma_t12_dir / "all_samples_spectra.csv")
    assert len(measurements) == 230
    lab_rows = np.genfromtxt(
        ma_t12_dir / "all_samples_instrument_lab_d65_10.csv",
        delimiter=",",
        skip_header=1,
        usecols=(2, 3, 4),
    )
    computed = np.concatenate([m.lab() for m in measurements])
    assert computed.shape == lab_rows.shape == (2760, 3)
    assert delta_E_CIE2000(computed, lab_rows).max() <= 0.01


@pytest.mark.parametrize("conditions", ["D65/10", "A/2", "F11/10", "D50/2"])
def test_matrix_weighting_equals_colour_science_sd_to_XYZ(conditions):
    cond = Conditions.parse(conditions)
    rng = np.random.default_rng(3)
    R = rng.uniform(0, 1, 31)
    sd = colour.SpectralDistribution(R, WAVELENGTHS)
    from flakelab.core.colorimetry import OBSERVERS

    expected = (
        colour.sd_to_XYZ(
            sd,
            colour.MSDS_CMFS[OBSERVERS[cond.observer]],
            colour.SDS_ILLUMINANTS[cond.illuminant],
            method="ASTM E308",
        )
        / 100
    )
    np.testing.assert_allclose(reflectance_to_XYZ(R, conditions=cond), expected, rtol=1e-9)


def test_perfect_white_is_L100_and_neutral_and_grey_scales():
    np.testing.assert_allclose(reflectance_to_Lab(np.ones(31)), [100, 0, 0], atol=1e-9)
    # Y = 0.5 → L* = 116·0.5^(1/3) − 16 (CIE 15)
    assert reflectance_to_Lab(np.full(31, 0.5))[0] == pytest.approx(116 * 0.5 ** (1 / 3) - 16)
    np.testing.assert_allclose(white_point()[1], 1.0)
    np.testing.assert_allclose(reflectance_to_sRGB(np.ones(31)), [1, 1, 1], atol=2e-3)


def test_vectorised_over_samples_and_geometries_equals_one_by_one():
    R = np.random.default_rng(0).uniform(0, 1, (4, 6, 31))
    batched = reflectance_to_Lab(R)
    single = np.array([[reflectance_to_Lab(R[i, j]) for j in range(6)] for i in range(4)])
    np.testing.assert_allclose(batched, single)


def test_resample_keeps_smooth_spectra_and_colour():
    R = 0.4 + 0.3 * np.sin(WAVELENGTHS / 40.0)
    coarse = resample(R, WAVELENGTHS, SHAPE_RENDER)
    assert coarse.shape == (16,)
    np.testing.assert_allclose(coarse, R[::2], atol=1e-12)  # 20 nm points are on the 10 nm grid
    back = resample(coarse, SHAPE_RENDER.wavelengths)
    assert delta_E_CIE2000(reflectance_to_Lab(back), reflectance_to_Lab(R)) < 0.2


def test_resample_onto_wavelengths_given_is_colour_science_s_alignment():
    """Spectra resampled onto a grid whose every wavelength they give (Otsu's 380–730 nm
    basis onto storage's 400–700 nm, 5 nm onto 10 nm) take those values at once: what
    colour-science's alignment returns, to 1e-12, for rough spectra as for smooth ones."""
    import colour

    from flakelab.core.spectra import SHAPE_STORE

    rng = np.random.default_rng(3)
    for start, end, step in ((380, 730, 10), (400, 700, 5), (360, 780, 10)):
        wl = np.arange(start, end + step / 2, step, dtype=float)
        spectra = rng.uniform(0.0, 1.0, (7, wl.size))
        aligned = colour.MultiSpectralDistributions(spectra.T, wl).copy().align(SHAPE_STORE)
        np.testing.assert_allclose(resample(spectra, wl), aligned.values.T, atol=1e-12)


def test_unknown_illuminant_and_observer_rejected_with_message():
    with pytest.raises(ValueError, match="expected an illuminant"):
        Conditions.parse("D66/10")
    with pytest.raises(ValueError, match="expected observer"):
        Conditions.parse("D65/5")


def test_the_defaults_name_the_conditions_and_tolerance_the_core_defines():
    """The command line's defaults (named where nothing is imported) are what the core means
    by its own: CIELAB under D65/10°, and a shipped tolerance preset."""
    from flakelab.core.colorimetry import D65_10
    from flakelab.core.defaults import DEFAULT_CONDITIONS, DEFAULT_TOLERANCE
    from flakelab.core.tolerance import TOLERANCE_PRESETS

    assert Conditions.parse(DEFAULT_CONDITIONS) == D65_10 == Conditions("D65", "10")
    assert DEFAULT_TOLERANCE in TOLERANCE_PRESETS


RECOVERED = np.array(
    [
        [50.0, 20.0, -30.0],  # a blue
        [130.0, -3.0, 2.0],  # an aluminium near specular: a reflectance factor over 1
        [0.5, 0.2, 0.1],  # near black
        [0.0, 0.0, 0.0],  # black
        [30.0, -40.0, 10.0],  # a green
        [40.0, 60.0, -80.0],  # a vivid violet
        [95.0, -5.0, 80.0],  # a vivid yellow
    ]
)


@pytest.mark.parametrize("conditions", [D65_10, Conditions("D50", "2"), Conditions("A", "10")])
def test_a_spectrum_recovered_from_lab_gives_that_lab_under_its_conditions(conditions):
    """Colours across the object colours, from black to a near-specular L* 130 and vivid hues:
    each recovered spectrum is non-negative and gives its L*a*b* under the conditions it was
    stated for, to ΔE00 1e-6. Otsu's basis alone missed the green by 0.81 ΔE00."""
    R = reflectance_from_Lab(RECOVERED, conditions=conditions)
    assert R.shape == (len(RECOVERED), WAVELENGTHS.size) and R.min() >= 0.0
    assert np.all(R[3] == 0.0)  # black reflects nothing
    assert R[1].max() > 1.0
    lab = reflectance_to_Lab(R, conditions=conditions)
    assert delta_E_CIE2000(lab, RECOVERED).max() < 1e-6


def test_a_recovered_spectrum_is_a_metamer_not_the_measurement(ma_t12_files):
    """The six real MA-T12 readings, each recovered from its own L*a*b*: the same colour in
    daylight at every geometry, another spectrum (0.045-0.33 apart at worst), so that under
    illuminant A the two part by 0.64-3.85 ΔE00 at the worst geometry. Hence no metamerism index
    is taken against a recovered spectrum, and its colour under another light is an estimate."""
    under_a = Conditions("A", "10")
    for file in ma_t12_files:
        measured = read_measurement(file)
        R = reflectance_from_Lab(measured.lab())
        assert delta_E_CIE2000(reflectance_to_Lab(R), measured.lab()).max() < 1e-6
        assert np.abs(R - measured.reflectance).max() > 0.04
        apart = delta_E_CIE2000(reflectance_to_Lab(R, conditions=under_a), measured.lab(under_a))
        assert apart.max() > 0.6


def test_a_dark_reading_s_noise_is_recovered_dipping_below_zero_as_measured_spectra_do():
    """Near black an instrument's noise gives colours no surface reflects: a dark metallic's
    45as110 of L* -0.27 in the harness's world (its measured spectrum down to -4e-4), L* 0.04
    with b* -1.1. Allowed to dip to -0.05, as the readers allow a measured spectrum, each is
    recovered exactly, dipping a few 1e-4; without, each is refused. A vivid colour no
    instrument's noise explains (L* 50, a* 130) is refused either way."""
    noisy = np.array([[-0.27, -0.09, -0.31], [0.04, -0.33, -1.12], [0.0, 5.0, 0.0]])
    R = reflectance_from_Lab(noisy, floor=-0.05)
    assert delta_E_CIE2000(reflectance_to_Lab(R), noisy).max() < 1e-6
    assert -0.003 < R.min() < 0.0
    for lab in noisy:
        with pytest.raises(UnreachableColour):
            reflectance_from_Lab([lab])
    with pytest.raises(UnreachableColour, match="nor one dipping no lower than -0.05"):
        reflectance_from_Lab([[50.0, 130.0, 0.0]], floor=-0.05)
    # a colour a surface reflects is recovered without a dip, floor or none
    within = reflectance_from_Lab(RECOVERED, floor=-0.05)
    np.testing.assert_array_equal(within, reflectance_from_Lab(RECOVERED))


def test_a_colour_no_surface_reflects_is_refused_by_its_position():
    with pytest.raises(UnreachableColour) as caught:
        reflectance_from_Lab([[50.0, 0.0, 0.0], [50.0, 130.0, 0.0]])
    assert caught.value.position == 1
    assert "no colour a surface reflects under D65/10" in str(caught.value)
    with pytest.raises(UnreachableColour):
        reflectance_from_Lab([[0.0, 5.0, 0.0]])  # black has no hue
