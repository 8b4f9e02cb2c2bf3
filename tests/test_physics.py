"""Coating optics: Monte Carlo invariants, Kubelka–Munk, the fast model and its path tables."""

from __future__ import annotations

import signal

import colour
import numpy as np
import pytest

from flakelab.core.spectra import WAVELENGTHS
from flakelab.io import read_library
from flakelab.library import LibraryError
from flakelab.library.optics import flake_reflectance, fresnel_reflectance
from flakelab.physics.fast import predict, single_collision
from flakelab.physics.kubelka_munk import (
    inverse_saunderson,
    km_coefficients,
    ks_ratio,
    layer_reflectance,
    reflectance_infinite,
    saunderson,
)
from flakelab.physics.layer import (
    Layer,
    interface_directions,
    internal_diffuse_reflectance,
    layer_from_fractions,
    mean_projected_cosine,
)
from flakelab.physics.montecarlo import ROUND_PHOTONS, simulate
from flakelab.physics.scaling import _de00, _lab
from flakelab.texture.readings import texture_readings

W = WAVELENGTHS.size
GEOMETRIES = ["45as-15", "45as15", "45as45", "45as110"]


def layer(rate=0.0, sd=10.0, kappa=0.0, sigma=0.0, g=0.0, H=15.0, primer=0.05, n=1.5, R=None):
    R = flake_reflectance(np.arange(91.0), WAVELENGTHS)[None] if R is None else R
    return Layer(
        np.array([[rate]]),
        np.radians([sd]),
        R,
        np.array([False]),
        np.full((1, W), kappa),
        np.full((1, W), sigma),
        np.full(1, g),
        H,
        np.full(W, primer),
        n,
    )


def within(a, b, stderr, sigmas=4.0):
    return np.all(np.abs(a - b) <= sigmas * stderr)


def test_white_primer_without_interface_is_a_perfect_diffuser():
    result = simulate(layer(primer=1.0, n=1.0), GEOMETRIES, 500, seed=1)
    np.testing.assert_allclose(result.brdf, 1 / np.pi, rtol=1e-12)


def test_white_primer_under_clearcoat_matches_the_fresnel_lambertian_limit():
    # inside: Lambertian, every internal reflection returned; f = T_i T_o / (n² π (1 − r_i))
    result = simulate(layer(primer=1.0), GEOMETRIES, 40_000, seed=2)
    _, _, T_in, T_out = interface_directions(GEOMETRIES)
    expected = T_in * T_out / (1.5**2 * np.pi * (1 - internal_diffuse_reflectance()))
    assert within(result.brdf[:, 0], expected, result.stderr[:, 0])


def test_lossless_layer_returns_all_light_that_entered():
    mirror = np.ones((1, 91, W))
    result = simulate(layer(rate=0.3, primer=1.0, R=mirror), GEOMETRIES, 5_000, seed=3)
    _, _, T_in, _ = interface_directions(GEOMETRIES)
    assert result.capped == 0
    np.testing.assert_allclose(result.albedo, T_in[0], rtol=1e-9)


def test_albedo_never_exceeds_what_entered():
    result = simulate(layer(rate=0.25, sigma=0.2, g=0.4, kappa=0.01), GEOMETRIES, 5_000, seed=4)
    _, _, T_in, _ = interface_directions(GEOMETRIES)
    assert np.all(result.albedo <= T_in[0]) and np.all(result.albedo > 0)


def test_reciprocity_swapping_light_and_detector():
    # 45as15: light at 45°, detector 30° on the far side; 30as-15 is the same pair swapped
    coating = layer(rate=0.2, kappa=0.02, sigma=0.1, g=0.3)
    forward = simulate(coating, ["45as15"], 40_000, seed=5)
    backward = simulate(coating, ["30as-15"], 40_000, seed=6)
    combined = np.hypot(forward.stderr, backward.stderr)
    assert within(forward.brdf, backward.brdf, combined)
    assert np.all(combined < 0.01 * forward.brdf)


@pytest.mark.parametrize(("kappa", "g"), [(0.01, 0.0), (0.05, 0.0), (0.02, 0.5)])
def test_thick_scattering_layer_reaches_kubelka_munk(kappa, g):
    # no flakes, no interface, diffuse light: the two-flux limit with K = 2κ, S = ¾σ(1 − g)
    coating = layer(kappa=kappa, sigma=1.0, g=g, H=2000.0, primer=0.0, n=1.0)
    result = simulate(coating, ["45as45"], 20_000, seed=7, diffuse_illumination=True)
    K, S = km_coefficients(kappa, 1.0, g)
    assert abs(result.albedo[0] - reflectance_infinite(K, S)) < 0.01


@pytest.mark.slow  # a validation run: Monte Carlo films, 40,000 paths a band, 15 s
def test_each_band_of_a_scatterer_is_traced_as_its_own_medium():
    """Bands ride one path, but physics keeps them apart: a film whose scattering halves
    from 400 to 700 nm (a white's σ, 1.5 µm over a white primer) reads at each band what a
    film of that band's σ throughout reads. With the bands' plain mean share as the chance
    of a real collision, the last band's weight was a product of factors spread over
    decades, and it read 0.004 of contrast over black and white where its own medium reads
    0.16 (history-aware spectral tracking, Kutz et al. 2017)."""
    sigma = np.linspace(13.2, 6.7, W)
    for primer in (0.0, 0.9):
        spread = simulate(layer(sigma=sigma, kappa=0.005, H=1.5, primer=primer), ["45as45"],
                          40_000, seed=14)  # fmt: skip
        for band in (0, W // 2, W - 1):
            own = simulate(layer(sigma=sigma[band], kappa=0.005, H=1.5, primer=primer),
                           ["45as45"], 40_000, seed=15)  # fmt: skip
            a, b = spread.brdf[0, band], own.brdf[0, band]
            stderr = np.hypot(spread.stderr[0, band], own.stderr[0, band])
            assert abs(a - b) <= 4 * stderr and abs(a / b - 1) < 0.03, (primer, band, a, b)


def test_single_collision_is_the_first_term_of_the_path_table():
    coating = layer(rate=0.25, sd=5.0)
    geometries = ["45as15", "45as25", "45as45"]
    result = simulate(coating, geometries, 40_000, seed=8)
    one_bounce = result.table.weight[:, 1].sum(-1) * result.table.reflectance[15]
    np.testing.assert_allclose(
        single_collision(coating, geometries)[0, :, 15], one_bounce, rtol=0.02
    )


def test_path_table_predicts_a_dyed_layer_from_the_dye_free_one():
    base = layer(rate=0.25)
    dye = 0.05 * (1 + np.sin(WAVELENGTHS / 40.0))
    dyed = base.with_absorption(dye[None])
    table = simulate(base, GEOMETRIES, 30_000, seed=9).table
    truth = simulate(dyed, GEOMETRIES, 30_000, seed=10)
    predicted = table.brdf(dyed.absorption)[0]
    assert np.all(np.abs(predicted / truth.brdf - 1) < 4 * truth.stderr / truth.brdf + 0.01)


def test_seed_makes_the_monte_carlo_reproducible():
    a = simulate(layer(rate=0.2), ["45as45"], 2_000, seed=11)
    b = simulate(layer(rate=0.2), ["45as45"], 2_000, seed=11, chunks=3)
    c = simulate(layer(rate=0.2), ["45as45"], 2_000, seed=12)
    np.testing.assert_allclose(a.brdf, b.brdf, rtol=1e-12)
    assert not np.allclose(a.brdf, c.brdf)


def test_progress_counts_every_photon_once_round_by_round():
    photons = 2 * 3 * ROUND_PHOTONS + 5  # three chunks: the last chunk's third round is short
    traced = []
    simulate(layer(rate=0.2), ["45as45"], photons, seed=11, chunks=3, progress=traced.append)
    assert traced == [3 * ROUND_PHOTONS, 3 * ROUND_PHOTONS, 5]


@pytest.mark.skipif(not hasattr(signal, "setitimer"), reason="no interval timer (Windows)")
def test_a_long_run_stops_within_a_round_or_two_of_a_signal():
    """Compiled code holds the interpreter, and a signal's handler runs only when it returns:
    one compiled call for the whole run kept a Ctrl-C or SIGTERM waiting until the run had
    ended (hours at 10⁹ photons; ``timeout`` could not stop ``validate scaling``). The tracer
    returns every round, so here an alarm half a second in stops a run of 60 rounds (about
    15 s on two cores) after a few."""

    class Stopped(Exception):
        pass

    def stop(_signum, _frame):
        raise Stopped

    coating, rounds = layer(rate=0.2, sigma=0.1), 60
    simulate(coating, GEOMETRIES, 2, seed=1)  # compiled (or loaded) before the alarm is set
    traced = []
    previous = signal.signal(signal.SIGALRM, stop)
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.5)
        with pytest.raises(Stopped):
            photons = rounds * 8 * ROUND_PHOTONS
            simulate(coating, GEOMETRIES, photons, seed=1, chunks=8, progress=traced.append)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    assert len(traced) < rounds / 10, f"stopped after {len(traced)} of {rounds} rounds"


def test_one_run_refuses_two_illumination_angles():
    with pytest.raises(ValueError, match="one illumination"):
        simulate(layer(), ["45as45", "15as15"], 100)


def test_fresnel_at_the_clearcoat_matches_colour_science():
    angles = np.array([0.0, 20.0, 45.0, 60.0, 80.0])
    stack = np.array([[1.0], [1.5], [1.5]])
    R_colour = colour.phenomena.multilayer_tmm(stack, [100.0], [550.0], angles)[0]
    reference = R_colour[0, :, 0, :].mean(axis=-1)  # [wavelength, angle, thickness, s/p]
    np.testing.assert_allclose(
        fresnel_reflectance(np.cos(np.radians(angles)), 1.0, 1.5), reference, atol=1e-10
    )


def test_projected_cosine_of_flat_flakes_is_the_direction_cosine():
    d = np.array([[0.0, 0.0, 1.0], [np.sin(0.5), 0.0, np.cos(0.5)]])
    np.testing.assert_allclose(mean_projected_cosine(d, np.radians(0.01)), d[:, 2], rtol=1e-6)


class TestKubelkaMunk:
    def test_ks_round_trip(self):
        R = np.linspace(0.02, 0.98, 9)
        ratio = ks_ratio(R)
        np.testing.assert_allclose(reflectance_infinite(ratio, 1.0), R, rtol=1e-12)

    def test_thin_clear_layer_is_beer_lambert(self):
        np.testing.assert_allclose(layer_reflectance(0.02, 0.0, 10.0, 0.8), 0.8 * np.exp(-0.4))

    def test_thick_layer_hides_the_substrate(self):
        for substrate in (0.0, 1.0):
            assert np.isclose(
                layer_reflectance(0.1, 2.0, 500.0, substrate), reflectance_infinite(0.1, 2.0)
            )

    def test_a_layer_that_scatters_and_does_not_absorb_has_kubelka_s_limit(self):
        """K = 0 (pearls alone: they scatter and do not absorb) is the limit of K → 0,
        (R_g + (1 − R_g)SX) / (1 + (1 − R_g)SX); the hyperbolic form's b·coth(bSX) read 0
        there, and such a layer reflected everything."""
        S, X, Rg = 0.05, 30.0, np.array([0.0, 0.3, 0.9])
        limit = (Rg + (1 - Rg) * S * X) / (1 + (1 - Rg) * S * X)
        np.testing.assert_allclose(layer_reflectance(0.0, S, X, Rg), limit, rtol=1e-12)
        np.testing.assert_allclose(layer_reflectance(1e-9, S, X, Rg), limit, rtol=1e-6)
        # nor scatters: the substrate, through a clear layer
        np.testing.assert_allclose(layer_reflectance(0.0, 0.0, X, Rg), Rg, atol=1e-9)

    def test_saunderson_round_trip(self):
        R = np.linspace(0.0, 0.95, 7)
        np.testing.assert_allclose(inverse_saunderson(saunderson(R)), R, atol=1e-12)


class TestFastModel:
    library = read_library(None)

    def predict_and_trace(self, recipe):
        coating = layer_from_fractions(self.library, self.library.fractions(recipe))
        geometries = ["45as-15", "45as15", "45as25", "45as45", "45as75", "45as110"]
        return predict(coating, geometries)[0], simulate(coating, geometries, 40_000, seed=13)

    def test_aluminium_with_a_dye_agrees_with_the_monte_carlo(self):
        fast, mc = self.predict_and_trace({"Al medium": 0.95, "Phthalo blue GS": 0.05})
        de = _de00(mc.brdf, fast)
        assert de.mean() < 0.8 and de.max() < 1.5

    def test_a_blend_of_aluminiums_shows_each_one_s_lobe(self):
        """A 5° VMP with a 15° fine aluminium reflects as the sum of their two lobes. One
        lobe at their mean spread, as the fast model read a blend before stop 115, was 5.9
        ΔE00 from the Monte Carlo (13.9 at 45as-15, 0.83 against 1.55 of reflectance); each
        lobe at its own spread 1.3 (2.2)."""
        fast, mc = self.predict_and_trace({"Al fine dark": 0.712, "Al VMP": 0.288})
        de = _de00(mc.brdf, fast)
        assert de.mean() < 2.0 and de.max() < 3.0

    def test_light_a_white_scatters_off_the_flake_paths_comes_back_diffuse(self):
        """Aluminium with 5 % TiO2: the light the white scatters out of the flake paths
        returns as diffuse light, as much as the Monte Carlo's within a fifth at the flop.
        Before stop 115 the diffuse channel gave back a fraction of it: 16.5 ΔE00 from the
        Monte Carlo at 45as110 (0.08 against 0.20 at 550 nm); now 3.5 at most."""
        fast, mc = self.predict_and_trace({"Al medium": 0.95, "Titanium dioxide white": 0.05})
        de = _de00(mc.brdf, fast)
        assert de.mean() < 4.0 and de.max() < 4.5
        np.testing.assert_allclose(fast[-1, 15], mc.brdf[-1, 15], rtol=0.2)

    def test_a_trace_of_black_in_a_pure_pearl_moves_it_little(self):
        """A pearl alone and with 0.01 % of carbon black: under 1 ΔE00 apart by the fast
        model, as by the Monte Carlo (0.6 L* at 45as110). Before the two-flux layer had its
        K = 0 limit, the pure pearl lost its diffuse light: L* 3.7 at 45as110 against 12.6
        with the trace and the Monte Carlo's 17.1."""
        pure, pure_mc = self.predict_and_trace({"Pearl interference green": 1.0})
        traced, _ = self.predict_and_trace(
            {"Pearl interference green": 0.9999, "Carbon black": 0.0001}
        )
        assert _de00(pure, traced).max() < 1.0
        flop = _lab(pure)[-1, 0], _lab(pure_mc.brdf)[-1, 0]  # L* at 45as110
        assert abs(flop[0] - flop[1]) < 5.0

    def test_a_solid_colour_is_lambertian_under_the_fresnel_top(self):
        geometries = ["45as-15", "45as15", "45as25", "45as45", "45as75", "45as110"]
        recipe = {"Titanium dioxide white": 0.9, "Phthalo blue GS": 0.1}
        fast = predict(layer_from_fractions(self.library, self.library.fractions(recipe)),
                       geometries)[0]  # fmt: skip
        _, _, T_in, T_out = interface_directions(geometries)
        body = fast / (T_in * T_out)[:, None]
        np.testing.assert_allclose(body, np.broadcast_to(body[:1], body.shape), rtol=1e-9)

    def test_more_dye_darkens_every_geometry(self):
        x = np.zeros((3, len(self.library.toners)))
        names = self.library.names
        for row, c in enumerate((0.0, 0.02, 0.06)):
            x[row, names.index("Al coarse")] = 1 - c
            x[row, names.index("Phthalo blue GS")] = c
        f = predict(layer_from_fractions(self.library, x), ["45as15", "45as75"])
        assert np.all(np.diff(f[:, :, 20], axis=0) < 0)

    def test_a_batch_predicts_each_formulation_as_it_would_alone(self):
        """Rows with and without pearls, aluminium or pigment only, in one batch: each row as
        if predicted alone, colour and texture (the pearl channel computes only the rows that
        hold pearls, and a layer only the reflectance tables of the species its rows hold)."""
        recipes = [
            {"Al medium": 0.95, "Phthalo blue GS": 0.05},
            {"Pearl interference green": 0.7, "Carbon black": 0.3},
            {"Titanium dioxide white": 0.9, "Phthalo blue GS": 0.1},
            {"Al coarse": 0.5, "Pearl interference green": 0.5},
        ]
        geometries = ["45as-15", "45as15", "45as45", "45as110"]
        x = np.array([self.library.fractions(r) for r in recipes])
        batch = predict(layer_from_fractions(self.library, x), geometries)
        alone = [predict(layer_from_fractions(self.library, row), geometries)[0] for row in x]
        np.testing.assert_allclose(batch, np.array(alone), rtol=1e-12)
        radius = [t.radius_um for t in self.library.toners if t.kind in ("aluminium", "pearl")]
        texture = texture_readings(layer_from_fractions(self.library, x), radius)
        alone = [texture_readings(layer_from_fractions(self.library, row), radius)[0] for row in x]
        np.testing.assert_allclose(texture, np.array(alone), rtol=1e-12)

    def test_an_atlas_saved_reads_back_and_a_save_cut_short_keeps_the_file(
        self, tmp_path, monkeypatch
    ):
        """``scripts/make_flake_atlas.py`` saves through a temporary file: the atlas read back
        is the one saved, and a Ctrl-C in the save leaves the file there as it was (numpy
        wrote into the shipped file itself)."""
        from flakelab.physics.fast import load_atlas

        shipped = load_atlas()
        path = tmp_path / "flake-atlas.npz"
        shipped.save(path)
        back = load_atlas(path)
        np.testing.assert_array_equal(back.laplace, shipped.laplace.astype(np.float32))
        assert (back.geometries, back.photons, back.seed) == (
            shipped.geometries, shipped.photons, shipped.seed)  # fmt: skip
        before = path.read_bytes()

        def cut_short(handle, **arrays):
            handle.write(b"PK\x03\x04 half an archive")
            raise KeyboardInterrupt

        monkeypatch.setattr(np, "savez_compressed", cut_short)
        with pytest.raises(KeyboardInterrupt):
            shipped.save(path)
        assert path.read_bytes() == before and [p.name for p in tmp_path.iterdir()] == [path.name]

    def test_atlas_lobes_are_multilinear_and_summed(self):
        """The compiled lobes: the 16-corner interpolation agrees with scipy's multilinear
        interpolation of the same table at random points (spread, depth per lobe; ρ, κ' per
        band), and each formulation gets the weighted sum of its own lobes' exponentials."""
        from scipy.interpolate import RegularGridInterpolator

        from flakelab.physics.fast import _summed_lobes

        rng = np.random.default_rng(5)
        table = rng.normal(size=(4, 5, 6, 7, 3))  # [spread, depth, ρ, κ', G]
        P, W = 9, 11
        first = np.array([0, 4, 5])  # three formulations: lobes 0–3, 4, 5–8
        weight = rng.uniform(0.1, 1.0, P)
        s, d = rng.uniform(0, 3, P), rng.uniform(0, 4, P)
        r, k = rng.uniform(0, 5, (P, W)), rng.uniform(0, 6, (P, W))
        cells = [
            np.minimum(np.floor(v).astype(int), n - 2) for v, n in ((s, 4), (d, 5), (r, 6), (k, 7))
        ]
        got = _summed_lobes(table, first, weight, cells[0], s - cells[0], cells[1], d - cells[1],
                            cells[2], r - cells[2], cells[3], k - cells[3])  # fmt: skip
        axes = [np.arange(n, dtype=float) for n in table.shape[:4]]
        points = np.stack(np.broadcast_arrays(s[:, None], d[:, None], r, k), axis=-1)
        log_lobes = np.stack(
            [RegularGridInterpolator(axes, table[..., g])(points) for g in range(3)], axis=1
        )  # [P, G, W]
        lobes = weight[:, None, None] * np.exp(log_lobes)
        want = np.stack([lobes[0:4].sum(0), lobes[4], lobes[5:9].sum(0)])
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)

    def test_fractions_must_match_the_library(self):
        with pytest.raises(ValueError, match="columns"):
            layer_from_fractions(self.library, np.ones((1, 3)))
        with pytest.raises(LibraryError, match="unknown toner"):
            self.library.fractions({"Unobtainium": 1.0})
