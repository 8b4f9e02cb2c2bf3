"""Measurement, flop index and tolerances."""

from __future__ import annotations

import numpy as np
import pytest

from flakelab.core import Geometry, Limit, Measurement, Tolerance, compare, flop_index
from flakelab.core.spectra import WAVELENGTHS
from flakelab.core.tolerance import TextureLimit, failing_geometries, tolerance_preset
from flakelab.io import read_tolerance


def _grey_metallic(L_levels: dict[str, float]) -> Measurement:
    """Neutral spectra whose L* at each geometry is given (Y from the CIE L* inverse)."""
    names = list(L_levels)
    L = np.array([L_levels[n] for n in names])
    Y = ((L + 16) / 116) ** 3
    return Measurement(
        "grey",
        tuple(Geometry.parse(n) for n in names),
        WAVELENGTHS,
        np.repeat(Y[:, None], 31, axis=1),
    )


def test_flop_index_from_spectra_matches_formula():
    m = _grey_metallic({"45as15": 110.0, "45as45": 50.0, "45as110": 20.0})
    np.testing.assert_allclose(m.lab()[:, 0], [110, 50, 20])
    assert m.flop_index() == pytest.approx(2.69 * 90**1.11 / 50**0.86)
    assert flop_index(110, 50, 20) == pytest.approx(13.7356, abs=1e-3)
    # a solid colour (no angular dependence) has zero flop
    assert _grey_metallic({"45as15": 50, "45as45": 50, "45as110": 50}).flop_index() == 0
    assert _grey_metallic({"45as15": 50, "45as45": 50}).flop_index() is None


def test_a_black_read_at_zero_or_below_has_no_flop_index():
    """The index divides by L*45: a black read as zero (a light trap, a carbon black solid),
    or just below it by the instrument's noise, has none. It was NaN, with a RuntimeWarning,
    and 'inspect --json' wrote the NaN no JSON reader takes."""
    import warnings

    names = tuple(Geometry.parse(n) for n in ("45as15", "45as45", "45as110"))
    zero = np.zeros((3, 31))
    below = zero.copy()
    below[1] = -0.002  # within REFLECTANCE_RANGE: instrument noise on black
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for reflectance in (zero, below):
            assert Measurement("black", names, WAVELENGTHS, reflectance).flop_index() is None
        assert np.isnan(flop_index([10.0, 10.0], [0.0, -0.5], [5.0, 5.0])).all()


def test_measurement_rejects_inconsistent_data():
    g = (Geometry.parse("45as15"),)
    with pytest.raises(ValueError, match="expected reflectance of shape"):
        Measurement("x", g, WAVELENGTHS, np.ones((2, 31)))
    with pytest.raises(ValueError, match="finite"):
        Measurement("x", g, WAVELENGTHS, np.full((1, 31), np.nan))
    with pytest.raises(ValueError, match="texture readings among"):
        Measurement("x", g, WAVELENGTHS, np.ones((1, 31)), texture={"sparkle": 1.0})


def test_tolerance_component_limits_and_per_geometry_override():
    tol = Tolerance("t", Limit(dL=1.0, dC=0.5), {"45as15": Limit(de00=3.0)})
    passed = tol.passes(
        ["45as15", "45as45", "45as75"],
        de00=[2.9, 0.3, 0.3],
        dLCH=np.array([[2.5, 0, 0], [0.9, -0.4, 5.0], [0.2, 0.6, 0]]),
    )
    assert passed.tolist() == [True, True, False]
    assert failing_geometries(["45as15", "45as45", "45as75"], passed) == ["45as75"]


def test_compare_reports_failing_geometries_only():
    ref = _grey_metallic({"45as15": 100, "45as45": 50, "45as110": 20})
    smp = _grey_metallic({"45as15": 100, "45as45": 50.5, "45as110": 22})
    result = compare(ref, smp, "de00-1.0")
    assert result.to_dict()["failing_geometries"] == ["45as110"]
    # the share of the limit used: ΔE00 itself against 1.0, above 1 only where it fails
    np.testing.assert_allclose(result.limit_share, result.de00, rtol=1e-12)
    assert [row["limit_share"] > 1 for row in result.to_dict()["geometries"]] == [
        not ok for ok in result.passed
    ]
    assert result.de00[0] == pytest.approx(0, abs=1e-9)


def test_a_comparison_says_which_geometries_its_verdict_leaves_out():
    ref = _grey_metallic({"45as15": 100, "45as45": 50, "45as110": 20})
    smp = _grey_metallic({"45as-15": 120, "45as45": 50, "45as110": 20})
    result = compare(ref, smp, "de00-1.0")
    assert result.geometries == ("45as45", "45as110") and result.all_pass
    assert result.to_dict()["not_compared"] == {"reference": ["45as15"], "sample": ["45as-15"]}
    assert compare(ref, ref).not_compared == {"reference": [], "sample": []}


def test_tolerance_files_validated(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[default]\nde00 = -1\n")
    with pytest.raises(ValueError, match="default: expected a positive limit for de00"):
        read_tolerance(bad)
    bad.write_text('[default]\nde00 = 1\n[geometries."45xx15"]\nde00 = 1\n')
    with pytest.raises(ValueError, match="geometries.45xx15: expected a geometry name"):
        read_tolerance(bad)
    bad.write_text("[default]\nde0 = 1\n")
    with pytest.raises(ValueError, match="expected keys among de00, dL, dC, dH"):
        read_tolerance(bad)
    bad.write_text('[default]\nde00 = "abc"\n')  # said "could not convert string to float"
    with pytest.raises(ValueError, match="bad.toml: default: de00: expected a number, got 'abc'"):
        read_tolerance(bad)
    bad.write_bytes(b"\x89PNG\r\n")  # was an internal error
    with pytest.raises(ValueError, match="bad.toml: not a UTF-8 text .* tolerance file"):
        read_tolerance(bad)
    good = tmp_path / "good.json"
    good.write_text('{"name": "j", "default": {"de00": 1.5}, "kL": 2}')
    assert read_tolerance(good).kL == 2 and read_tolerance(good).limit("45as15").de00 == 1.5
    # a table where limits belong, a value where a table belongs: named, not a TypeError
    for text, where in [
        ("default = 1.0\n", "default: expected a table of limits"),
        ("geometries = 2\n[default]\nde00 = 1\n", "geometries: expected a table"),
        ("texture = 0.5\n[default]\nde00 = 1\n", "texture: expected a table of limits"),
        ("[default]\nde00 = 1\n[texture]\nG = 0\n", "texture: expected a positive limit for G"),
        ("[default]\nde00 = 1\n[texture]\ngraininess = 1\n", "expected keys among G, SG, Si"),
        # tighter than any instrument can judge; 1e-320 overflowed the share of the limit
        ("[default]\ndE00 = 1\n", "expected keys among de00"),
        ("[default]\ndL = 1e-320\n", "expected a limit for dL of at least 0.01, got 1e-320"),
        # read before: a tolerance called "nan", kL = nan or true
        ("name = nan\n[default]\nde00 = 1\n", "name: expected a text, got nan"),
        ("kL = nan\n[default]\nde00 = 1\n", "kL: expected a number from 0.1 to 10.0, got nan"),
        ("kC = true\n[default]\nde00 = 1\n", "kC: expected a number from 0.1 to 10.0, got True"),
        ("kH = 1e-320\n[default]\nde00 = 1\n", "kH: expected a number from 0.1 to 10.0"),
    ]:
        bad.write_text(text)
        with pytest.raises(ValueError, match=where):
            read_tolerance(bad)
    bad.with_suffix(".json").write_text("[1.0]")
    with pytest.raises(ValueError, match="expected a table with a default limit"):
        read_tolerance(bad.with_suffix(".json"))


def test_texture_limits_read_round_trip_and_bound_each_light_s_sparkle(tmp_path):
    """``[texture]`` in a tolerance file bounds |ΔG|, |ΔSG| and, under each of the three
    lights, |ΔSi| and |ΔSa|; what is not listed is not judged."""
    path = tmp_path / "shop.toml"
    path.write_text("[default]\nde00 = 1.0\n[texture]\nG = 0.8\nSi = 1.5\n")
    tol = read_tolerance(path)
    assert tol.texture == TextureLimit(G=0.8, Si=1.5)
    assert Tolerance.from_dict(tol.to_dict()) == tol
    assert read_tolerance("refinish").to_dict()["texture"] == {"G": 1.0, "SG": 0.5}
    reference = {"Sa15": 5.0, "Si15": 5.0, "Si45": 5.0, "Si75": 5.0, "SG": 1.6, "G": 3.0}
    sample = {"Sa15": 9.0, "Si15": 6.8, "Si45": 5.3, "Si75": 3.8, "SG": 4.0, "G": 3.4}
    shares = tol.texture_share(reference, sample)
    assert shares == pytest.approx({"Si15": 1.2, "Si45": 0.2, "Si75": 0.8, "G": 0.5})
    assert Tolerance("colour", Limit(de00=1.0)).texture_share(reference, sample) == {}


def test_compare_judges_texture_where_the_tolerance_bounds_it():
    """The same colour, one unit of graininess apart and a half: the refinish tolerance
    (|ΔG| ≤ 1) fails it on texture alone, naming G; the colour-only de00-1.0 passes it."""
    levels = {"45as15": 100, "45as45": 50, "45as110": 20}
    reference = _grey_metallic(levels)
    reference = Measurement(**{**vars(reference), "texture": {"SG": 2.0, "G": 3.0}})
    grainier = Measurement(**{**vars(reference), "texture": {"SG": 2.1, "G": 4.5}})
    judged = compare(reference, grainier, "refinish")
    assert judged.passed.all() and not judged.all_pass
    report = judged.to_dict()
    assert report["failing_geometries"] == [] and report["failing_texture"] == ["G"]
    assert report["texture_limit_share"] == pytest.approx({"SG": 0.2, "G": 1.5})
    assert report["limit_share_max"] == pytest.approx(1.5) and not report["pass"]
    assert compare(reference, grainier, "de00-1.0").all_pass
    assert compare(reference, reference, "refinish").all_pass
    assert tolerance_preset("refinish").texture is not None


def test_standards_rank_by_the_worst_share_of_the_limit_as_each_pair_is_compared():
    """Standards of a deck ranked for one sample, nearest first: each one's ΔE00, shares,
    texture and verdict are those of compare() on that pair alone, whether the standards
    share the sample's geometries or some of them, on its wavelength grid or another; one
    sharing no geometry is left out; texture ranks too (the grainier twin falls behind)."""
    from dataclasses import replace

    import colour

    from flakelab.core.comparison import rank_references
    from flakelab.core.spectra import resample

    rng = np.random.default_rng(3)
    sample = _grey_metallic({"45as15": 100, "45as45": 50, "45as110": 20})
    sample = replace(sample, texture={"G": 3.0})
    standards = []
    for k in range(12):
        shifted = sample.reflectance * np.exp(rng.normal(0, 0.02, (3, 1)))
        standards.append(replace(sample, sample=f"chip {k}", reflectance=shifted))
    standards[4] = replace(standards[4], texture={"G": 4.6})  # its colour fine, its grain not
    standards[5] = standards[5].select(["45as45", "45as110"])
    fine = colour.SpectralShape(380, 730, 5)
    finer = resample(standards[6].reflectance, WAVELENGTHS, fine)
    standards[6] = replace(standards[6], wavelengths=fine.wavelengths, reflectance=finer)
    standards.append(_grey_metallic({"45as-15": 100}))
    ranked = rank_references(standards, sample, "refinish")
    assert len(ranked) == 12 and "grey" not in [r.reference.sample for r in ranked]
    shares = [r.share for r in ranked]
    assert shares == sorted(shares)
    for r in ranked:
        judged = compare(r.reference, sample, "refinish")
        report = judged.to_dict()
        assert r.geometries == judged.geometries
        np.testing.assert_allclose(r.de00, judged.de00, atol=1e-9)
        assert r.share == pytest.approx(report["limit_share_max"], abs=1e-9)
        assert r.passes == judged.all_pass
    grainy = next(r for r in ranked if r.reference.sample == "chip 4")
    assert grainy.to_dict()["limit_share_at"] == "G" and not grainy.passes


def test_real_readings_rank_next_to_their_own_pigment(ma_t12_dir):
    """The 230 real MA-T12 readings of the Polychromy database (historical pigments in egg
    white, Punic wax and other binders, over several grounds) as a deck: for each, the
    nearest of the others holds the same pigment for 86 % of them (pigment_list.csv; 198
    of 229), and the nearest one's figures are those compare() gives the pair."""
    import csv

    from flakelab.core.comparison import rank_references
    from flakelab.io import read_measurements

    readings = read_measurements(ma_t12_dir / "all_samples_spectra.csv")
    with open(ma_t12_dir / "pigment_list.csv", newline="") as listed:
        pigment = {row["Name"]: row["Pigment"] for row in csv.DictReader(listed)}
    same = []
    for k, reading in enumerate(readings):
        nearest = rank_references(readings[:k] + readings[k + 1 :], reading, "refinish")[0]
        if {reading.sample, nearest.reference.sample} <= set(pigment):
            same.append(pigment[reading.sample] == pigment[nearest.reference.sample])
        if k % 50 == 0:
            judged = compare(nearest.reference, reading, "refinish")
            np.testing.assert_allclose(nearest.de00, judged.de00, atol=1e-9)
    assert len(same) == 229 and np.mean(same) > 0.8


def test_readings_of_one_surface_average_and_say_how_far_each_lies():
    """Three readings of a grey: the mean's spectra are the readings' mean (resampled to the
    storage grid where a file used another), texture averaged where all hold it; a reading
    5 % darker is the furthest, and identical readings lie nowhere from their mean."""
    from dataclasses import replace

    from flakelab.core.comparison import spread_of_readings
    from flakelab.core.measurement import mean_reading
    from flakelab.errors import FlakelabError

    base = _grey_metallic({"45as15": 90.0, "45as45": 50.0, "45as110": 20.0})
    readings = [
        replace(base, sample="a", texture={"G": 2.0, "Si15": 4.0}),
        replace(base, sample="b", reflectance=base.reflectance * 1.01, texture={"G": 3.0}),
        replace(base, sample="c", reflectance=base.reflectance * 0.95, texture={"G": 4.0}),
    ]
    mean = mean_reading(readings)
    np.testing.assert_allclose(mean.reflectance, base.reflectance * (1 + 1.01 + 0.95) / 3)
    assert mean.texture == {"G": 3.0} and mean.sample == "mean of 3 readings (a, b, c)"
    spread = spread_of_readings(readings, mean, tolerance_preset("refinish"))
    assert spread["furthest"] == "c" and spread["limit_share_max"] > 0.5
    assert len(spread["de00_from_mean_max"]) == 3
    same = [replace(base, sample=s) for s in "xyz"]
    assert spread_of_readings(same, mean_reading(same), tolerance_preset("refinish"))[
        "limit_share_max"
    ] == pytest.approx(0.0, abs=1e-9)
    fine = replace(base, sample="d", wavelengths=np.arange(400.0, 701.0, 5.0),
                   reflectance=np.repeat(base.reflectance[:, :1], 61, axis=1))  # fmt: skip
    np.testing.assert_allclose(mean_reading([base, fine]).reflectance, base.reflectance)
    fewer = _grey_metallic({"45as15": 90.0, "45as45": 50.0})
    with pytest.raises(FlakelabError, match="reading 'grey': geometries 45as15, 45as45 differ"):
        mean_reading([readings[0], fewer])
    with pytest.raises(FlakelabError, match="instrument 'ma-t12' differs from 'a'"):
        mean_reading([readings[0], replace(base, instrument="ma-t12")])


def test_readings_at_different_geometries_stack_at_every_geometry_any_was_read_at():
    """Panels read by two instruments stack at the union of their geometries, in instrument
    order (the 15° lamp's first, each lamp's by aspecular angle), each panel's spectra where
    it was read and NaN elsewhere; its texture readings likewise."""
    from dataclasses import replace

    from flakelab.core.geometry import instrument_geometries
    from flakelab.core.measurement import TEXTURE_READINGS, stacked_readings
    from flakelab.data import example_path
    from flakelab.io import read_measurement

    car = read_measurement(example_path("target"))
    five = car.select(instrument_geometries("five-angle"))
    bare = replace(read_measurement(example_path("sprayout")), texture={})
    geometries, spectra, texture = stacked_readings([five, bare])
    assert [g.name for g in geometries] == [
        "15as-45", "15as-30", "15as-15", "15as15", "15as45", "15as80",
        "45as-15", "45as15", "45as25", "45as45", "45as75", "45as110",
    ]  # fmt: skip
    read = [geometries.index(g) for g in five.geometries]
    np.testing.assert_array_equal(spectra[0, read], five.storage_spectra(five.geometries))
    assert np.isnan(np.delete(spectra[0], read, axis=0)).all()
    np.testing.assert_array_equal(spectra[1], bare.storage_spectra(geometries))
    np.testing.assert_array_equal(texture[0], [car.texture[k] for k in TEXTURE_READINGS])
    assert texture.shape == (2, 8) and np.isnan(texture[1]).all()
