"""Physical flake images and texture metrics respond as physics says (issue 6, first part)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import spearmanr

from flakelab.texture.images import FlakePopulation, flake_image
from flakelab.texture.metrics import graininess, sparkle


def population(radius: float, rate: float) -> FlakePopulation:
    return FlakePopulation(np.array([radius]), np.array([rate]), np.array([10.0]),
                           np.array([0.88]))  # fmt: skip


def test_sparkle_area_grows_with_flake_concentration():
    rates = [0.01, 0.02, 0.04, 0.08, 0.16]
    areas = [sparkle(flake_image(population(10, r), 45.0, seed=3))[0] for r in rates]
    assert spearmanr(rates, areas).statistic >= 0.9


def test_sparkle_intensity_and_graininess_grow_with_flake_size():
    radii = [4.0, 7.0, 10.0, 15.0, 22.0]
    intensity = [sparkle(flake_image(population(a, 0.1), 45.0, seed=4))[1] for a in radii]
    grain = [graininess(flake_image(population(a, 0.1), "diffuse", seed=4)) for a in radii]
    assert spearmanr(radii, intensity).statistic >= 0.9
    assert spearmanr(radii, grain).statistic >= 0.9


def test_images_are_seeded_and_calibrated_to_a_white_diffuser():
    a = flake_image(population(10, 0.1), 15.0, seed=5)
    np.testing.assert_array_equal(a, flake_image(population(10, 0.1), 15.0, seed=5))
    assert not np.array_equal(a, flake_image(population(10, 0.1), 15.0, seed=6))
    # no flakes: the background alone, far below a white diffuser, and nothing sparkles
    empty = flake_image(population(10, 0.0), 45.0, seed=5)
    assert np.allclose(empty, 0.02) and sparkle(empty) == (0.0, 0.0)


def test_unknown_light_is_refused():
    with pytest.raises(ValueError, match="light"):
        flake_image(population(10, 0.1), 30.0)


def test_a_texture_reading_counts_the_glints_of_one_spot():
    from flakelab.texture.readings import GLINT_SD, GLINT_SHARE, GRAIN_SD, counted_readings

    expected = np.array([[6.0, 5.0, 2.0, 5.0, 0.5, 5.0, 0.0, 3.0], np.zeros(8)])
    expected[0, 6] = np.sqrt(expected[0, [0, 2, 4]] * expected[0, [1, 3, 5]]).sum() / 6
    many = np.repeat(expected, 20000, axis=0)
    read = counted_readings(many, np.random.default_rng(7), glint_share=GLINT_SHARE,
                            glint_sd=GLINT_SD, grain_sd=GRAIN_SD)  # fmt: skip
    coating, bare = read[:20000], read[20000:]
    assert not bare.any()  # no flakes, no glint and no grain
    # unbiased, with the spread of a count: Var(Sa) = glint_share·Sa, sd(G)/G = grain_sd
    np.testing.assert_allclose(coating.mean(0)[[0, 1, 2, 3, 7]], expected[0, [0, 1, 2, 3, 7]],
                               rtol=0.01)  # fmt: skip
    np.testing.assert_allclose(coating[:, [0, 2, 4]].var(0), GLINT_SHARE * expected[0, [0, 2, 4]],
                               rtol=0.05)  # fmt: skip
    assert coating[:, 7].std() / 3.0 == pytest.approx(GRAIN_SD, rel=0.05)
    # fewer glints, a less certain mean brightness: Si at 75° varies most
    assert coating[:, 5].std() > 2 * coating[:, 1].std()
    # each reading's sparkle grade is its own Sa and Si's
    grade = np.sqrt(coating[:, [0, 2, 4]] * coating[:, [1, 3, 5]]).sum(1) / 6
    np.testing.assert_allclose(coating[:, 6], grade)


@pytest.mark.slow  # a validation run: rendered flake populations, 15 s
def test_the_world_s_texture_noise_is_the_spot_to_spot_spread_of_rendered_images():
    from flakelab.cases.generator import World
    from flakelab.io import read_library
    from flakelab.texture.images import flake_populations
    from flakelab.texture.readings import SPARKLE_LIGHT_SLOPE
    from flakelab.texture.repeatability import fit_counting_noise, fit_light_slope, spot_readings

    world = World(read_library(None))
    x = world.formulations(40, np.random.default_rng(11))
    x = x[world.library.paint_families(x) != "solid"][:3]
    populations = flake_populations(world.layer(x, world.nominal(3)), world.library.flake_radii_um)
    spots = [spot_readings(p, 6, seed=100 * i) for i, p in enumerate(populations)]
    fitted = fit_counting_noise(spots)
    for name, value in fitted.items():
        assert 0.5 < getattr(world.settings, name) / value < 2.0, name
    # and the images' Si rises with the light's angle as the world's readings do
    assert 0.5 < SPARKLE_LIGHT_SLOPE / fit_light_slope(spots) < 2.0


def test_sparkle_intensity_rises_with_the_light_s_angle_and_nothing_else_does():
    from flakelab.cases.generator import World
    from flakelab.core.measurement import TEXTURE_FAMILIES
    from flakelab.io import read_library
    from flakelab.texture.readings import SPARKLE_LIGHT_SLOPE, SPARKLE_LIGHTS, light_factor

    # a mirror shows the lamp's radiance, the white standard gets cos θ of its irradiance
    assert light_factor(0.0) == 1.0
    assert light_factor(60.0) == pytest.approx(1 + SPARKLE_LIGHT_SLOPE * np.log10(2.0))
    world = World(read_library(None))
    x = world.formulations(30, np.random.default_rng(3))
    _, texture = world.appearance(x, world.nominal(30))
    Si = texture[:, TEXTURE_FAMILIES["Si"]]
    shows = Si[:, 0] > 0
    assert shows.sum() > 10
    # the same coating's Si under each light differs by the light's factor alone
    factors = light_factor(np.array(SPARKLE_LIGHTS)) / light_factor(SPARKLE_LIGHTS[0])
    np.testing.assert_allclose(Si[shows] / Si[shows, :1], np.tile(factors, (shows.sum(), 1)))
    assert (np.diff(Si[shows], axis=1) > 0).all()
