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
