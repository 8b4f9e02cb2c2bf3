"""Appearance-based texture generation and rendering (issue 6): the patch process keeps its
definition, the fitted processes return the values asked of them, texture keeps colour."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter
from scipy.stats import spearmanr

from flakelab.core.colorimetry import linear_sRGB_to_Lab, reflectance_to_Lab
from flakelab.core.difference import delta_E_CIE2000 as delta_E00
from flakelab.core.geometry import INSTRUMENT_GEOMETRIES, flake_angles_at
from flakelab.data import example_path
from flakelab.io import read_measurement
from flakelab.render.appearance import (
    SPARKLE_ANGLES,
    _periodic_blur,
    appearance_of,
    cardinal_spline,
    compose,
    glint_along,
    lamps_of,
    parse_distance,
    render_curved,
    render_panel,
    render_stack,
    render_under_lamps,
    texture_images,
)
from flakelab.texture.calibration import (
    AnchorPanel,
    _fit_anchor,
    measure_texture,
    roundtrip,
    shipped_processes,
)
from flakelab.texture.generator import UNITS, control_values, patch_image
from flakelab.texture.images import FlakePopulation
from flakelab.texture.metrics import graininess


@pytest.fixture(scope="module")
def appearance():
    return appearance_of(read_measurement(example_path("target")))


def test_patch_process_mean_is_count_times_patch_light():
    # E[image] = count · E[amplitude] · 2πσ²; log-uniform amplitudes average g·(1 − 1/s)/ln s
    size, grey, count, sparkler = 3.0, 2.0, 0.05, 20.0
    image = patch_image(size, grey, count, sparkler, (512, 512), np.random.default_rng(1))
    sigma = size / (2 * np.sqrt(2 * np.log(2)))
    expected = count * grey * (1 - 1 / sparkler) / np.log(sparkler) * 2 * np.pi * sigma**2
    assert image.mean() == pytest.approx(expected, rel=0.03)
    assert patch_image(size, grey, 0.0, 1.0, (64, 64), np.random.default_rng(0)).max() == 0.0


def test_control_forms_are_the_papers():
    constants = np.array([[0.0, 0.0, 1.0], [1.0, 2.0, 0.5], [np.log(3.0), 0.0, 1.0], [0, 1, 2]])
    glint = control_values("glint", constants, 4.0)
    assert glint["size"] == pytest.approx(51.0 * UNITS["glint"]["size"])  # 1 + 100/(1 + e^0)
    assert glint["grey"] == pytest.approx((1 + 100 / (1 + np.exp(1 + 2 * 2.0))) * 10.0)
    assert glint["count"] == pytest.approx((1 + 100 / 4) * UNITS["glint"]["count"])
    coarse = control_values("coarseness", constants, 4.0)
    assert coarse["grey"] == pytest.approx((1 + 2 * 4**0.5) * UNITS["coarseness"]["grey"])
    assert coarse["sparkler"] == pytest.approx(16.0)


def test_anchor_fit_recovers_a_known_process():
    truth = dict(size=4.0, grey=1.5, count=0.3, sparkler=10.0)
    image = patch_image(**truth, shape=(256, 256), rng=np.random.default_rng(3))
    population = FlakePopulation(
        np.array([10.0]), np.array([0.1]), np.array([10.0]), np.array([0.9])
    )
    anchor = AnchorPanel(population, image, measure_texture("coarseness", image))
    controls = _fit_anchor("coarseness", anchor, (256, 256), 8)
    fitted = dict(zip(("size", "grey", "count", "sparkler"), controls, strict=True))
    again = patch_image(**fitted, shape=(512, 512), rng=np.random.default_rng(9))
    assert graininess(again) == pytest.approx(anchor.value, rel=0.08)
    assert again.mean() == pytest.approx(image.mean(), rel=0.05)


def test_a_coarseness_form_stays_positive_across_its_ladder():
    """The sparklers a fresh fit found per anchor: one large value at the bottom. A power law
    fitted to them in linear units crossed zero at G 7 (clamped there, the closed loop missed
    by 15 %); fitted to their logarithms it stays inside its domain over the whole ladder."""
    from flakelab.texture.calibration import _fit_form, _power_law

    values = np.array([2.64, 3.47, 4.76, 6.67, 8.69, 11.38, 14.6, 18.99, 22.13])
    sparkler = np.array([1697.5, 145.5, 23.4, 24.7, 17.1, 21.6, 20.6, 22.1, 18.4])
    form = _fit_form("coarseness", values, sparkler)
    assert _power_law(np.geomspace(values[0], values[-1], 200), *form).min() > 10
    assert _power_law(values[0], *form) > 500  # and still follows the bottom anchor


@pytest.mark.parametrize("process", ["coarseness", "glint"])
def test_closed_loop_returns_the_prescribed_texture(process):
    report = roundtrip(shipped_processes()[process], points=5, size_px=768, seed=7)
    assert report["rel_error_max"] <= 0.10, report


def test_rendered_grain_is_as_strong_as_the_anchor_panels():
    """The coarseness texture the renderer draws at each anchor's graininess has the contrast
    of that anchor's physical flake image (both tone-mapped, within a factor 1.6), from the
    bottom of the ladder up: graininess alone, a coefficient of variation, cannot tell a
    faint pattern from a strong one, so the grey level must follow the anchors' brightness
    (a grey level that fell to zero at G 2.64 drew no grain at all there)."""
    from flakelab.render.appearance import _tone
    from flakelab.texture.calibration import ANCHOR_PX, anchor_panels

    for anchor in anchor_panels("coarseness", size_px=ANCHOR_PX, seed=0):
        _, drawn = texture_images(1.0, anchor.value, (256, 512), seed=4)
        ratio = drawn.std() / _tone(anchor.image).std()
        assert 1 / 1.6 < ratio < 1.6, (anchor.value, ratio)


def test_texture_sweeps_follow_per_column_values():
    processes = shipped_processes()
    glint = np.geomspace(*processes["glint"].value_range, 6)
    columns = np.repeat(glint, 128)
    raw = processes["glint"].image(np.broadcast_to(columns, (768, columns.size)), seed=2)
    measured = [measure_texture("glint", raw[:, i * 128 : (i + 1) * 128]) for i in range(6)]
    assert spearmanr(glint, measured).statistic >= 0.9


@pytest.mark.parametrize("diffuse_fraction", [0.0, 0.7, 1.0])
def test_texture_does_not_change_colour(appearance, diffuse_fraction):
    for aspecular in appearance.aspecular:
        options = dict(diffuse_fraction=diffuse_fraction, seed=int(aspecular) + 40)
        plain = render_panel(appearance, aspecular, 256, texture=False, **options)
        textured = render_panel(appearance, aspecular, 256, **options)
        assert np.ptp(textured[..., 1]) > 0.05  # the texture is there
        lab = linear_sRGB_to_Lab(np.stack([plain.mean((0, 1)), textured.mean((0, 1))]))
        assert delta_E00(lab[0], lab[1]) <= 0.5, aspecular


def test_compose_keeps_column_means_where_light_allows():
    rng = np.random.default_rng(0)
    texture = rng.gamma(0.3, 0.3, size=(300, 4))
    colour = np.array([[0.02, 0.03, 0.1], [0.2, 0.3, 0.4], [0.6, 0.6, 0.6], [0.9, 0.95, 0.99]])
    image = compose(colour, texture)
    assert image.min() >= 0 and image.max() <= 1
    np.testing.assert_allclose(image.mean(axis=0), colour, atol=2e-3)


def test_cardinal_spline_passes_knots_and_keeps_lines():
    x = np.array([-15.0, 15, 25, 45, 75, 110])
    line = 3 * x[:, None] + np.array([1.0, -2.0])
    at = np.linspace(-15, 110, 50)
    np.testing.assert_allclose(cardinal_spline(x, line, at), 3 * at[:, None] + [1.0, -2.0])
    y = np.sin(x / 30)[:, None]
    np.testing.assert_allclose(cardinal_spline(x, y, x), y)
    assert cardinal_spline(x, y, np.array([200.0]))[0, 0] == pytest.approx(y[-1, 0])


def test_curved_panel_shows_measured_colour_and_gloss(appearance):
    image = render_curved(appearance, (8, 221), diffuse_fraction=0.0, texture=False, gloss=0.5)
    columns = np.linspace(0, 110, 221)
    for angle, lab in zip(appearance.aspecular, appearance.Lab, strict=True):
        if 0 <= angle <= 110:
            j = int(np.argmin(abs(columns - angle)))
            got = linear_sRGB_to_Lab(image[0, j])
            if image[0, j].max() < 0.999:  # inside the display's range
                assert delta_E00(got, lab) < 0.5, angle
    brightness = image[0].sum(axis=1)
    assert np.argmax(brightness) < 5  # the clearcoat's highlight sits at specular


SOURCE_45 = [g for g in INSTRUMENT_GEOMETRIES["ma-t12"] if g.startswith("45as")]


def test_an_ma_t12_reading_is_drawn_under_each_of_its_lamps():
    """Under its 15° lamp, from the geometries that lamp lit, as under its 45° lamp: a colour
    at 45° from specular is the 15as45 reading's, not the 45as45's."""
    target = read_measurement(example_path("target"))  # the MA-T12's twelve geometries
    five = target.select(INSTRUMENT_GEOMETRIES["five-angle"])
    assert lamps_of(target) == (45.0, 15.0) and lamps_of(five) == (45.0,)
    low = appearance_of(target, lamp=15)
    lit = [g for g in target.geometry_names if g.startswith("15as")]
    np.testing.assert_allclose(low.aspecular, [-45, -30, -15, 15, 45, 80])
    np.testing.assert_allclose(low.Lab, reflectance_to_Lab(target.select(lit).reflectance))
    image = render_curved(low, (8, 161), diffuse_fraction=0.0, texture=False, gloss=0.0)
    columns = np.linspace(0, 80, 161)  # to the last angle the lamp lit
    high = appearance_of(target)
    for angle in (15.0, 45.0, 80.0):
        got = linear_sRGB_to_Lab(image[0, int(np.argmin(abs(columns - angle)))])
        assert delta_E00(got, low.Lab[list(low.aspecular).index(angle)]) < 0.5, angle
    got = linear_sRGB_to_Lab(image[0, 90])  # 45°
    assert delta_E00(got, high.Lab[list(high.aspecular).index(45.0)]) > 1.0
    stacks = render_under_lamps([target, target], band_px=8, width_px=32, texture=False)
    assert [(s.lamp, s.span, s.interpolated_from) for s in stacks] == [
        (45.0, (0.0, 110.0), ()),
        (15.0, (0.0, 80.0), ()),
    ]
    assert all(s.image.shape == (16, 32, 3) for s in stacks)
    assert [s.lamp for s in render_under_lamps([target, five], band_px=8, width_px=32)] == [45.0]
    # lamps asked for: those not read by every reading interpolated from each one's 45° lamp
    asked = render_under_lamps([target, five], lamps=[15.0, 45.0], band_px=8, width_px=32)
    assert [(s.lamp, s.span, s.interpolated_from) for s in asked] == [
        (15.0, (0.0, 95.0), (45.0,)),
        (45.0, (0.0, 110.0), ()),
    ]
    alike = render_under_lamps([five, five], lamps=[15.0], band_px=8, width_px=32, seed=1)
    np.testing.assert_array_equal(alike[0].image[:8], alike[0].image[8:])
    drawn = render_under_lamps([target.select(SOURCE_45)], lamps=[15.0], band_px=1, width_px=96,
                               texture=False, diffuse_fraction=0.0, gloss=0.0)[0].image  # fmt: skip
    at_45 = linear_sRGB_to_Lab(drawn[0, round(45.0 / 95.0 * 95)])
    assert delta_E00(at_45, low.Lab[list(low.aspecular).index(45.0)]) < 0.5
    with pytest.raises(ValueError, match=r"a lamp at 30° needs .* it can be drawn under 45°, 15°"):
        appearance_of(target, lamp=30)
    one_each = target.select(["15as15", "45as45"])
    with pytest.raises(ValueError, match="lamp at 45° needs two or more .* got 15as15, 45as45"):
        render_under_lamps([one_each])


def test_glint_is_placed_by_the_flake_tilt_the_texture_camera_saw(appearance):
    """The camera reads each lamp's glint along the normal (15as15, 45as45, 75as75): a panel
    under any lamp glints as the camera saw where its geometry needs the flake tilt the
    camera's did (DESIGN.md §7), not at the same aspecular angle."""
    from dataclasses import replace

    from scipy.optimize import brentq

    readings = replace(appearance, glint=np.array([1.0, 2.0, 3.0]))
    for lamp, glint in zip(SPARKLE_ANGLES, readings.glint, strict=True):
        under = replace(readings, lamp=lamp)
        assert glint_along(under, np.array([lamp]))[0] == pytest.approx(glint)
    # under the 45° lamp the 75° lamp's tilt (20°) is reached 62° from specular
    tilt = flake_angles_at(75.0, 75.0)[0]
    tilt_of_75 = brentq(lambda a: flake_angles_at(45.0, a)[0] - tilt, 45.0, 75.0)
    assert 60 < tilt_of_75 < 64
    np.testing.assert_allclose(glint_along(readings, np.array([tilt_of_75, 75.0])), [3.0, 3.0])
    assert 2.0 < glint_along(readings, np.array([55.0]))[0] < 3.0


def test_a_stack_is_each_paints_curved_panel_in_one_texture_draw(appearance):
    from dataclasses import replace

    darker = replace(appearance, Lab=appearance.Lab - [5.0, 0.0, 0.0])
    stack = render_stack([appearance, darker, appearance], band_px=24, width_px=96, seed=3)
    assert stack.shape == (72, 96, 3)
    np.testing.assert_array_equal(stack[:24], render_curved(appearance, (24, 96), seed=3))
    np.testing.assert_array_equal(stack[24:48], render_curved(darker, (24, 96), seed=3))
    np.testing.assert_array_equal(stack[48:], stack[:24])  # the same paint: the same band
    assert stack[24:48].mean() < stack[:24].mean()


def test_distance_softens_coarseness_and_dims_glints():
    near = texture_images(3.0, 15.0, (384, 384), distance_m=0.5, seed=1)
    far = texture_images(3.0, 15.0, (384, 384), distance_m=3.0, seed=1)
    assert far[1].std() < 0.6 * near[1].std()  # diffuse pattern: contrast falls
    assert far[0].max() < near[0].max()  # glints: dimmer
    assert np.sum(far[0] > 0.1) <= np.sum(near[0] > 0.1)


def test_from_far_off_the_coarseness_averages_out_without_running_out_of_memory():
    """The eye's blur grows with the distance; a kernel wider than the image is applied in
    Fourier space (at 1e9 m it was a 491 GiB kernel), the same blur where both apply."""
    near = texture_images(3.0, 15.0, (128, 256), distance_m=0.5, seed=1)[1]
    far = texture_images(3.0, 15.0, (128, 256), distance_m=1e9, seed=1)[1]
    farther = texture_images(3.0, 15.0, (128, 256), distance_m=1e12, seed=1)[1]
    assert far.std() < 1e-6 * near.std() and np.allclose(far, farther)  # flat: its mean alone
    image = np.random.default_rng(2).random((64, 128))
    for sigma in (3.0, 20.0):  # the filter's path, and the Fourier one (4σ beyond 64 rows)
        np.testing.assert_allclose(
            _periodic_blur(image, sigma), gaussian_filter(image, sigma, mode="wrap"), atol=2e-5
        )


def test_distance_parsing():
    assert parse_distance("0.5m") == 0.5
    assert parse_distance("50 cm") == pytest.approx(0.5)
    assert parse_distance("2") == 2.0
    for bad in ("far", "-1m", "0cm"):
        with pytest.raises(ValueError, match="distance"):
            parse_distance(bad)


def test_a_panel_seen_from_afar_is_drawn_as_from_a_kilometre():
    """Beyond 1 km the eye's blur already smooths any image drawn, so a farther panel is
    drawn as from 1 km: ``--distance 1e308m`` overflowed squaring the distance (an internal
    error). The blur grows with the distance up to there."""
    from flakelab.render.appearance import FARTHEST_DISTANCE_M, _eye_blur_px, texture_images

    blurs = [_eye_blur_px(d) for d in (0.5, 2.0, 10.0, FARTHEST_DISTANCE_M, 1e6, 1e308)]
    assert blurs[0] == 0.0 and blurs[1] < blurs[2] < blurs[3] == blurs[4] == blurs[5]
    assert blurs[3] > 8192  # wider than the widest image drawn
    far, farthest = (texture_images(1.0, 1.0, (32, 64), distance_m=d) for d in (1e3, 1e308))
    for a, b in zip(far, farthest, strict=True):
        assert np.isfinite(b).all() and np.array_equal(a, b)


def test_render_commands_write_images_of_the_asked_size(tmp_path, cli):
    from matplotlib.image import imread

    run = cli("render", "--view", "panel", "--size", "96", "-o", str(tmp_path / "p.png"))
    assert run.returncode == 0, run.stderr
    assert imread(tmp_path / "p.png").shape[:2] == (96, 96)
    run = cli("render", "--size", "128", "--distance", "2m", "-o", str(tmp_path / "c.png"))
    assert run.returncode == 0, run.stderr
    assert imread(tmp_path / "c.png").shape[:2] == (64, 128)
    run = cli("render-grid", "--steps", "3", "--tile", "32", "-o", str(tmp_path / "g.png"))
    assert run.returncode == 0, run.stderr
    assert imread(tmp_path / "g.png").shape[:2] == (96, 96)


def test_render_draws_the_panel_under_the_lamp_asked_for(tmp_path, cli):
    """``render --lamp 15`` draws an MA-T12 reading from what its 15° lamp lit: 45° from
    specular shows the 15as45 colour (sRGB's 8 bits allow ΔE00 0.5), not the 45as45 one; the
    reading's 45° readings alone draw about the same there, interpolated over flake tilt."""
    import colour
    from matplotlib.image import imread

    target = read_measurement(example_path("target"))
    measured = dict(zip(target.geometry_names, reflectance_to_Lab(target.reflectance), strict=True))
    for lamp, reading, other in (("15", "15as45", "45as45"), ("45", "45as45", "15as45")):
        out = tmp_path / f"lamp-{lamp}.png"
        run = cli("render", "--lamp", lamp, "--size", "161", "--no-texture", "--light", "0",
                  "-o", str(out))  # fmt: skip
        assert run.returncode == 0, run.stderr
        pixels = imread(out)[..., :3]
        span = 80.0 if lamp == "15" else 110.0
        drawn = linear_sRGB_to_Lab(colour.cctf_decoding(pixels[0, round(45.0 / span * 160)]))
        assert delta_E00(drawn, measured[reading]) < 0.5, lamp
        assert delta_E00(drawn, measured[other]) > 1.0, lamp
    # its 45° readings alone: the 15° lamp interpolated over flake tilt, and said so
    from flakelab.io import write_measurements

    lit_at_45 = tmp_path / "lit-at-45.csv"
    write_measurements([target.select([g for g in target.geometry_names if g[:2] == "45"])],
                       lit_at_45)  # fmt: skip
    out = tmp_path / "interpolated.png"
    run = cli("render", lit_at_45, "--lamp", "15", "--size", "161", "--no-texture", "--light",
              "0", "-o", str(out))  # fmt: skip
    said = " ".join(run.stderr.split())
    assert run.returncode == 0 and "was not read under a lamp at 15°: drawn from its 45°" in said
    pixels = imread(out)[..., :3]  # interpolated to 95° from specular: the detector within 80°
    drawn = linear_sRGB_to_Lab(colour.cctf_decoding(pixels[0, round(45.0 / 95.0 * 160)]))
    assert delta_E00(drawn, measured["15as45"]) < 0.8


def test_a_render_is_written_in_the_format_its_suffix_names(tmp_path, cli):
    """Every suffix ``--output`` takes gives a file of its format and the same pixels (JPEG:
    within its compression). Before, a ``.tif`` was refused "error: TIF": Pillow names
    the format "TIFF"."""
    from PIL import Image

    pixels = {}
    for name, fmt in (("r.png", "PNG"), ("r.tif", "TIFF"), ("r.TIFF", "TIFF"),
                      ("r.jpg", "JPEG"), ("r.jpeg", "JPEG")):  # fmt: skip
        run = cli("render", "--view", "panel", "--size", "32", "-o", str(tmp_path / name))
        assert run.returncode == 0, run.stderr
        with Image.open(tmp_path / name) as image:
            assert image.format == fmt and image.size == (32, 32)
            pixels[name] = np.asarray(image.convert("RGB"), dtype=float)
    for lossless in ("r.tif", "r.TIFF"):
        np.testing.assert_array_equal(pixels[lossless], pixels["r.png"])
    assert np.abs(pixels["r.jpg"] - pixels["r.png"]).mean() < 8


def test_the_shipped_coarseness_grey_level_is_what_its_refit_gives(tmp_path, cli):
    import json
    import shutil
    from importlib.resources import files

    from flakelab.texture.calibration import _SHIPPED

    shipped = Path(str(files("flakelab.data") / _SHIPPED))
    refitted = tmp_path / "processes.json"
    shutil.copy(shipped, refitted)
    document = json.loads(refitted.read_text())
    document["coarseness"]["constants"][1] = [53.1, -655.3, -2.54]  # the form shipped before
    refitted.write_text(json.dumps(document))
    run = cli("texture", "fit", "-o", str(refitted), "--grey-only")
    assert run.returncode == 0, run.stderr
    got, want = (json.loads(f.read_text()) for f in (refitted, shipped))
    # rtol: refits on different CPUs stop a few 1e-6 apart (the least-squares fit's default
    # tolerance over renders whose rounding differs); the form shipped before is far off
    np.testing.assert_allclose(got["coarseness"]["constants"], want["coarseness"]["constants"],
                               rtol=1e-4)  # fmt: skip
    assert got["glint"] == want["glint"]


def test_render_refuses_bad_input_without_writing(tmp_path, cli):
    from flakelab.io import write_measurements

    out = tmp_path / "x.png"
    one_each = tmp_path / "one-each.csv"
    target = read_measurement(example_path("target"))
    write_measurements([target.select(["15as15", "45as45"])], one_each)
    for args, message in [
        (("--distance", "near"), "distance"),
        (("--light", "1.5"), "Invalid value for '--light'"),  # named by its option
        (("--light", "nan"), "Invalid value for '--light'"),
        # the panel interpolates between measured angles; beyond them it would show the end
        (("--view", "panel", "--aspecular", "130"), "within the measured -15–110°"),
        (
            ("--view", "panel", "--aspecular", "100", "--lamp", "5"),
            "within the interpolated (from the 45° lamp's readings) -15–85°",
        ),
        (("--aspecular", "30"), "--aspecular: for --view panel"),  # the curved view sweeps
        ((str(tmp_path / "missing.cxf"),), "missing.cxf"),
        # a reading of one geometry under each lamp: nothing to draw, nor to interpolate from
        ((str(one_each), "--lamp", "30"), f"{one_each}: "),
        ((str(one_each), "--lamp", "30"), "two or more of them in plane"),
        ((str(one_each),), "a lamp at 45° needs two or more"),
    ]:
        run = cli("render", *args, "--size", "32", "-o", str(out))
        assert run.returncode == 2 and message in run.stderr, run.stderr
        assert "Traceback" not in run.stderr
    run = cli("render", "--size", "32", "-o", str(tmp_path / "x.bmp"))
    assert run.returncode == 2 and ".png" in run.stderr
    missing = tmp_path / "no" / "x.png"
    for command in ("render", "render-grid"):  # checked before the render, named as an option
        run = cli(command, "-o", str(missing))
        assert run.returncode == 2 and f"--output: {missing}: no folder" in run.stderr
    assert list(tmp_path.iterdir()) == [one_each]


def test_texture_grid_keeps_one_colour_in_every_tile(appearance):
    from flakelab.render.appearance import render_grid

    # Fig. 3 holds colour fixed: every tile's mean is the untextured colour of the same light
    steps, tile = 4, 96
    image = render_grid(appearance, steps, tile, diffuse_fraction=0.5, seed=1)
    tiles = image.reshape(steps, tile, steps, tile, 3).mean(axis=(1, 3)).reshape(-1, 3)
    plain = render_panel(appearance, 45.0, 8, diffuse_fraction=0.5, texture=False)
    reference = linear_sRGB_to_Lab(plain.mean(axis=(0, 1)))
    assert np.max(delta_E00(linear_sRGB_to_Lab(tiles), reference)) <= 0.5


def test_the_difference_chart_draws_what_the_tolerance_judges(monkeypatch, tmp_path):
    """Each sample's ΔL*, ΔC*, ΔH* and share of the limit, as Tolerance.judge gives them; the
    limits as bands where the tolerance bounds a component; failing geometries ringed; a line
    per illumination angle, dashed beyond the geometries set apart."""
    import flakelab.render.plots as plots
    from flakelab.core.tolerance import tolerance_preset

    drawn = {}
    monkeypatch.setattr(plots, "_save", lambda figure, path, dpi: drawn.update(figure=figure))
    reference = read_measurement(example_path("target"))
    names = reference.geometry_names  # MA-T12: six lit at 15°, six at 45°
    lab_reference = reference.lab()
    rng = np.random.default_rng(3)
    samples = {"a": lab_reference + rng.normal(0, 0.6, lab_reference.shape),
               "b": lab_reference + rng.normal(0, 1.2, lab_reference.shape)}  # fmt: skip
    components = tolerance_preset("components")
    plots.plot_differences(names, lab_reference, samples, components, tmp_path / "chart.png",
                           apart=9)  # fmt: skip
    dL, dC, dH, used = drawn["figure"].axes
    for index, lab in enumerate(samples.values()):
        de00, dLCH, passed = components.judge(names, lab_reference, lab)
        share = components.share_of_limit(names, de00=de00, dLCH=dLCH)
        for k, axis in enumerate((dL, dC, dH)):
            lines = [ln for ln in axis.get_lines() if ln.get_color() == f"C{index}"]
            # 15° light; 45° light up to the ninth geometry; the rest apart, dashed
            assert [len(ln.get_xdata()) for ln in lines] == [6, 3, 3]
            assert [ln.get_linestyle() for ln in lines] == ["-", "-", "--"]
            assert np.allclose(np.concatenate([ln.get_ydata() for ln in lines]), dLCH[:, k])
        ydata = [ln.get_ydata() for ln in used.get_lines() if ln.get_color() == f"C{index}"]
        assert np.allclose(np.concatenate(ydata), 100 * share)
        assert not passed.all() and passed.any()
    rings = np.concatenate([c.get_offsets()[:, 0] for c in used.collections])
    failing = [i for lab in samples.values() for i in np.flatnonzero(
        ~components.judge(names, lab_reference, lab)[2])]  # fmt: skip
    assert sorted(rings) == sorted(failing)
    band = dL.collections[0].get_paths()[0].vertices[:, 1]
    assert band.max() == pytest.approx(1.5) and band.min() == pytest.approx(-1.5)  # near specular
    # a ΔE00 tolerance bounds no component: no band, the axis spans at least its limit
    drawn.clear()
    plots.plot_differences(names, lab_reference, {"a": samples["a"]},
                           tolerance_preset("de00-1.0"), tmp_path / "chart.png")  # fmt: skip
    dL = drawn["figure"].axes[0]
    assert not dL.collections and dL.get_ylim()[1] >= 1.0


def test_the_difference_chart_draws_each_bounded_texture_reading_s_share(monkeypatch, tmp_path):
    """Texture shares join the share panel right of the geometries, one column per bounded
    reading, in each sample's colour; a reading over its limit is ringed."""
    import flakelab.render.plots as plots
    from flakelab.core.tolerance import tolerance_preset

    drawn = {}
    monkeypatch.setattr(plots, "_save", lambda figure, path, dpi: drawn.update(figure=figure))
    reference = read_measurement(example_path("target"))
    names, lab = reference.geometry_names, reference.lab()
    texture = {"a": {"SG": 0.4, "G": 1.3}, "b": {"SG": 0.2, "G": 0.5}}
    plots.plot_differences(names, lab, {"a": lab + 0.1, "b": lab - 0.1},
                           tolerance_preset("refinish"), tmp_path / "c.png",
                           texture=texture)  # fmt: skip
    used = drawn["figure"].axes[3]
    labels = [t.get_text() for t in used.get_xticklabels()]
    assert labels == [*names, "texture SG", "texture G"]
    for index, shares in enumerate(texture.values()):
        marks = [ln for ln in used.get_lines() if ln.get_marker() == "s"][index]
        aside = 0.15 * (index - 0.5)  # two samples, set apart about each reading's column
        assert np.allclose(marks.get_xdata(), [len(names) + 1 + aside, len(names) + 2 + aside])
        assert np.allclose(marks.get_ydata(), [100 * shares["SG"], 100 * shares["G"]])
    rings = np.concatenate([c.get_offsets() for c in used.collections if len(c.get_offsets())])
    assert np.allclose(rings, [[len(names) + 2 - 0.075, 130.0]])  # sample a's G: 1.3 of it
    # the colour panels keep the geometries alone
    assert [t.get_text() for t in drawn["figure"].axes[0].get_xticklabels()] == list(names)


def test_a_figure_s_long_title_is_broken_into_lines_as_wide_as_the_figure():
    """A verdict naming every one of an MA-T12's twelve geometries ran off the figure's side.
    Broken at spaces only: the correction chart's title, naming its model, was broken inside
    "demo-five-angle"."""
    import matplotlib.pyplot as plt

    from flakelab.render.plots import _fitted

    names = ", ".join(INSTRUMENT_GEOMETRIES["ma-t12"])
    title = f"PAR_PW_EB_CC_1 vs PAR_PW_GE_MC_2: FAIL at {names}"
    figure = plt.figure(figsize=(11, 4))
    lines = _fitted(title, figure).splitlines()
    assert len(lines) == 2 and all(len(line) <= 99 for line in lines)
    assert " ".join(lines) == title
    figure.set_figwidth(12)  # the difference chart's
    title = ("Blue metallic sprayout (synthetic) against Blue metallic target (synthetic): the "
             "correction by demo-five-angle 717120462ac3")  # fmt: skip
    lines = _fitted(title, figure).splitlines()
    plt.close(figure)
    assert len(lines) == 2 and " ".join(lines) == title
    assert any("demo-five-angle" in line for line in lines)


def test_against_flake_tilt_the_readings_under_both_lamps_fall_on_one_curve():
    """The example's L* under the 15° lamp, read off at the 45° lamp's abscissae where both
    reach: 4.0 apart on average against the aspecular angle, 0.95 against θ_flake, the
    flake-based parameter (DESIGN.md §2), as an effect paint's readings should."""
    from flakelab.core.geometry import flake_angles
    from flakelab.render.plots import flop_series

    target = read_measurement(example_path("target"))
    apart = {}
    for against in ("aspecular", "flake-tilt"):
        series = flop_series(target, against=against)
        assert list(series) == [15.0, 45.0]
        (x15, low), (x45, high) = series[15.0], series[45.0]
        assert np.all(np.diff(x15) >= 0) and np.all(np.diff(x45) >= 0)
        shared = (x45 >= x15.min()) & (x45 <= x15.max())
        apart[against] = np.abs(np.interp(x45[shared], x15, low[:, 0]) - high[shared, 0]).mean()
    lit = [g for g in target.geometries if g.illumination == 45]
    np.testing.assert_allclose(flop_series(target, against="flake-tilt")[45.0][0],
                               np.sort(flake_angles(lit)[0]))  # fmt: skip
    assert apart["flake-tilt"] < 0.4 * apart["aspecular"]
    with pytest.raises(ValueError, match="against: expected one of aspecular, flake-tilt"):
        flop_series(target, against="tilt")
