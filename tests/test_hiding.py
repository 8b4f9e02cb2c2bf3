"""How thick a basecoat must be to hide the primer, and over which grey
(:mod:`flakelab.physics.hiding`, ``flakelab hiding``)."""

from __future__ import annotations

import json
from dataclasses import replace

import colour
import numpy as np
import pytest

from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.geometry import FACE_GEOMETRY, instrument_geometries
from flakelab.core.measurement import Measurement
from flakelab.core.spectra import WAVELENGTHS
from flakelab.io import read_library, write_measurements
from flakelab.physics.fast import reflectance_factor
from flakelab.physics.hiding import (
    BUILD_GRID,
    GREY_SHADES,
    grey_primer,
    hiding,
    read_bare,
    under_basecoat,
)
from flakelab.physics.hiding import _where_it_falls_to as where_it_falls_to
from flakelab.physics.layer import layer_from_fractions

GEOMETRIES = instrument_geometries("ma-t12")
WHITE, BLACK = "Titanium dioxide white", "Carbon black"


def test_the_build_that_hides_is_read_where_the_trace_falls_for_good():
    """A trace linear in log build crosses the threshold where its line does, exactly (the
    interpolation is in log build); one that dips under and rises again hides only after it
    last falls; one always under hides at the grid's least, one never under never."""
    a, b, threshold = 2.0, 0.8, 1.0
    line = a - b * np.log(BUILD_GRID)
    dips = line.copy()
    dips[10] = 0.0  # under once, far too early
    traces = np.array([line, dips, np.full(BUILD_GRID.size, 0.5), np.full(BUILD_GRID.size, 3.0)])
    found = where_it_falls_to(traces, threshold)
    crossing = np.exp((a - threshold) / b)
    np.testing.assert_allclose(found[:2], crossing, rtol=1e-12)
    assert found[2] == pytest.approx(BUILD_GRID[0], rel=1e-12) and found[3] == np.inf


@pytest.fixture(scope="module")
def library():
    return read_library()


def test_more_paint_hides_more_and_a_white_makes_a_clear_red_hide_sooner(library):
    """Over a contrast chart, the black and the white show less through every solid as it is
    built up (the trace never rises); iron oxide red, the white and carbon black hide within
    one coat at a contrast ratio of 1, a phthalo blue masstone (a transparent pigment) hides
    at no build and over no grey, its contrast ratio under 0.05; and quinacridone red hides
    sooner the more white it holds (47 µm at 2 %, 3.4 µm at 40 %)."""
    solids = [{"Iron oxide red": 1}, {WHITE: 1}, {BLACK: 1}, {"Phthalo blue GS": 1}]
    found = hiding(library, np.array([library.fractions(r) for r in solids]), GEOMETRIES)
    assert np.all(np.diff(found.contrast_de00, axis=1) <= 1e-9)
    assert np.all(found.coats(found.hiding_um[:3]) == 1)
    assert np.all(found.contrast_ratio[:3] > 0.999)
    assert found.hiding_um[3] == np.inf and found.contrast_ratio[3] < 0.05
    assert found.best_primer[3] is None and np.all(np.isinf(found.primer_hiding_um[3]))
    whites = [library.fractions({"Quinacridone red": 1 - w, WHITE: w}) for w in (0.02, 0.1, 0.4)]
    tints = hiding(library, np.array(whites), GEOMETRIES)
    assert np.all(np.diff(tints.hiding_um) < 0) and np.all(np.isfinite(tints.hiding_um))


def test_a_paint_is_sprayed_over_the_grey_of_its_lightness_unless_another_saves_a_coat(library):
    """Neutral greys of white and carbon black, each hiding every primer in one coat, go over
    the grey nearest their own lightness (L* 91.6 over G1 … 31.5 over G7); bismuth vanadate
    (L* 77, nearest G2) goes over G1, white, over which it comes to its full colour in two
    coats where every other grey takes four. Over the grey chosen, a one-coat paint at the
    nominal build lies within the threshold of its full colour."""
    blacks = (0.0005, 0.005, 0.01, 0.03, 0.1, 0.3)
    greys = np.array([library.fractions({WHITE: 1 - b, BLACK: b}) for b in blacks])
    found = hiding(library, greys, GEOMETRIES)
    shades = np.array(list(GREY_SHADES.values()))
    nearest = [list(GREY_SHADES)[int(np.argmin(np.abs(shades - L)))] for L in found.lightness]
    assert found.best_primer == nearest
    assert len(set(nearest)) >= 5  # the greys span the shades
    chosen = [found.primers.index(p) for p in found.best_primer]
    assert np.all(found.primer_de00[np.arange(len(blacks)), chosen] <= found.threshold)
    yellow = hiding(library, library.fractions({"Bismuth vanadate yellow": 1})[None], GEOMETRIES)
    coats = yellow.coats(yellow.primer_hiding_um[0])
    assert yellow.best_primer == ["G1"] and coats[0] < coats[1:].min()
    assert nearest_grey(yellow.lightness[0]) != "G1"


def test_a_ground_under_no_film_reads_as_it_reads_bare(library):
    """A ground given as read bare at 45°:0° (a chart's white, a grey, a measured primer) is
    read back there through a film of no build; elsewhere it reads within 9 % of it, as far
    as the surface's Fresnel transmittance changes with the angles (45as110: 0.916 of it).
    :func:`read_bare` inverts :func:`under_basecoat`, and a ground reads darker bare than
    under the binder (a primer of Y 5 % bare reflects 11.5 % under it)."""
    bare = np.array([np.full(WAVELENGTHS.size, 0.80), grey_primer(50.0), OHTA["red"]])
    n = library.binder.refractive_index
    np.testing.assert_allclose(read_bare(under_basecoat(bare, n), n), bare, rtol=1e-12)
    assert float(under_basecoat(0.05, n)) == pytest.approx(0.115, abs=5e-4)
    assert np.all(under_basecoat(bare, n) > bare)
    layer = layer_from_fractions(library, library.fractions({WHITE: 1})[None])
    for ground in bare:
        thin = replace(layer, thickness=np.array([1e-9]), primer=under_basecoat(ground, n))
        read = reflectance_factor(thin, GEOMETRIES)[0] / ground  # [G, W]
        face = [g.name for g in GEOMETRIES].index(FACE_GEOMETRY)
        np.testing.assert_allclose(read[face], 1.0, rtol=1e-6)
        assert np.all(np.abs(read - 1) < 0.09) and read[-1] == pytest.approx(0.916, abs=1e-3)


OHTA = {
    name: colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"][name]
    .copy()
    .align(colour.SpectralShape(400, 700, 10))
    .values
    for name in (
        "white 9.5 (.05 D)",
        "neutral 8 (.23 D)",
        "neutral 6.5 (.44 D)",
        "neutral 5 (.70 D)",
        "neutral 3.5 (1.05 D)",
        "black 2 (1.5 D)",
        "red",
        "yellow",
    )  # fmt: skip
}
"""Real measured spectra, 400–700 nm: the ColorChecker's neutrals and two of its colours
(Ohta's measurements, shipped with colour-science)."""
NEUTRALS = list(OHTA)[:6]


def test_measured_neutral_primers_act_as_flat_greys_of_their_lightness(library):
    """A grey primer is taken as flat at its Y. The ColorChecker's measured neutrals (a*, b*
    within 1.1) as primers give what flat greys of their L* give: for eight paints (greys,
    a red tint, bismuth vanadate, a blue metallic, a phthalo tint), the same primer chosen,
    ΔE00 at the nominal build within 0.02 and the build that hides within 15 %."""
    measured = {name: OHTA[name] for name in NEUTRALS}
    lightness = reflectance_to_Lab(np.array(list(measured.values())))[:, 0]
    flat = {name: grey_primer(L) for name, L in zip(NEUTRALS, lightness, strict=True)}
    recipes = [{WHITE: 1 - b, BLACK: b} for b in (0.0005, 0.005, 0.03, 0.3)] + [
        {"Quinacridone red": 0.9, WHITE: 0.1}, {"Bismuth vanadate yellow": 1},
        {"Al medium": 0.7, "Phthalo blue GS": 0.3}, {"Phthalo blue GS": 0.7, WHITE: 0.3},
    ]  # fmt: skip
    x = np.array([library.fractions(r) for r in recipes])
    real, assumed = (hiding(library, x, GEOMETRIES, primers=p) for p in (measured, flat))
    assert real.best_primer == assumed.best_primer
    assert len(set(real.best_primer)) >= 4
    np.testing.assert_allclose(real.primer_de00, assumed.primer_de00, atol=0.02)
    np.testing.assert_allclose(real.primer_hiding_um, assumed.primer_hiding_um, rtol=0.15)


def test_a_coloured_primer_of_the_paints_own_colour_hides_it_soonest(library):
    """Among the ColorChecker's four mid neutrals and its red and yellow, a quinacridone red
    tint goes over the red, over which it reaches its full colour in 2.7 µm where the
    neutral nearest its lightness takes 9.5 (a coat more); neutral 8 hides it in one coat
    too, but the red lies nearer its colour: of the primers that take the fewest coats, the
    one nearest in ΔE*ab is chosen (so a neutral set picks by L*). Bismuth vanadate goes
    over the yellow."""
    primers = {name: OHTA[name] for name in (*NEUTRALS[1:5], "red", "yellow")}
    paints = [{"Quinacridone red": 0.9, WHITE: 0.1}, {"Bismuth vanadate yellow": 1}]
    found = hiding(library, np.array([library.fractions(r) for r in paints]), GEOMETRIES,
                   primers=primers)  # fmt: skip
    assert found.best_primer == ["red", "yellow"]
    red, neutral = found.primers.index("red"), found.primers.index("neutral 3.5 (1.05 D)")
    assert found.primer_hiding_um[0, red] == pytest.approx(2.7, abs=0.1)
    assert found.primer_hiding_um[0, neutral] == pytest.approx(9.5, abs=0.1)
    coats = found.coats(found.primer_hiding_um[0])
    assert coats[red] == 1 < coats[neutral] and coats[found.primers.index(NEUTRALS[1])] == 1
    nearest = np.argmin(found.primer_distance, axis=1)
    assert [found.primers[i] for i in nearest] == found.best_primer


def nearest_grey(lightness: float) -> str:
    shades = np.array(list(GREY_SHADES.values()))
    return list(GREY_SHADES)[int(np.argmin(np.abs(shades - lightness)))]


def test_cli_hiding_reports_each_recipe_and_refuses_what_it_cannot_read(tmp_path, cli):
    """``flakelab hiding``: a blue metallic and a clear red masstone: the metallic hides the
    chart in two coats and goes over a mid grey, where one coat does; the red hides nothing
    and is said so (null in JSON); --plot draws it. An unknown toner names its recipe file; a
    threshold out of range and a plot of no known format are refused, nothing drawn."""
    blue, red = tmp_path / "blue.json", tmp_path / "red.json"
    blue.write_text(json.dumps({"Al medium": 70, "Phthalo blue GS": 30}))
    red.write_text(json.dumps({"Quinacridone red": 100}))
    plot = tmp_path / "hiding.svg"
    done = cli("hiding", blue, red, "--instrument", "ma-t12", "--plot", plot, "--json")
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    metallic, clear = report["paints"]
    assert metallic["coats"] == 2 and metallic["best_primer"] in ("G4", "G5", "G6")
    best = next(g for g in metallic["primers"] if g["primer"] == metallic["best_primer"])
    assert best["coats"] == 1 and best["hiding_um"] < metallic["hiding_um"]
    assert clear["hiding_um"] is None and clear["best_primer"] is None
    assert "<svg" in plot.read_text()
    shown = cli("hiding", blue)
    assert shown.returncode == 0 and "over each grey" in shown.stdout
    said = cli("hiding", red)
    assert "does not hide within 119 µm" in " ".join(said.stdout.split())
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps({"Phthalo blu GS": 10}))
    refused = {
        f"{wrong}: recipe: unknown toner 'Phthalo blu GS'": [wrong],
        "--threshold": [blue, "--threshold", "0"],
        "--plot": [blue, "--plot", tmp_path / "hiding.xyz"],
    }
    for message, args in refused.items():
        done = cli("hiding", *args)
        assert done.returncode == 2 and message in " ".join(done.stderr.split()), done.stderr
    assert not (tmp_path / "hiding.xyz").exists()


def write_primers(path, names, geometries=GEOMETRIES, shine=None):
    """A measurement file of ColorChecker patches as primers, flat over ``geometries`` but for
    ``shine`` (name → added reflectance, falling from the gloss as an effect paint's does)."""
    readings = []
    for name in names:
        R = np.tile(OHTA[name], (len(geometries), 1))
        if shine and name in shine:
            R = R + shine[name] * np.exp(-np.array([g.aspecular for g in geometries]) / 30)[:, None]
        readings.append(Measurement(sample=name, geometries=geometries,
                                    wavelengths=WAVELENGTHS, reflectance=R))  # fmt: skip
    write_measurements(readings, path)
    return path


def test_cli_hiding_and_match_take_the_shops_own_primers(tmp_path, cli, monkeypatch):
    """``--primers FILE``: ``flakelab hiding`` reads each sample's 45°:0° reading as a primer
    and names the one to spray over, with its L*a*b*; ``match`` names it for each candidate.
    A panel that reads like no matte primer (bright near the gloss) is taken with a note. A
    sample without a 45°:0° reading, a name given twice and ``match evaluate --primers`` are
    refused, naming the file and the sample. A workplace sets its file once in
    FLAKELAB_PRIMERS; ``--primers`` overrides it, and one it cannot read is refused naming
    the variable."""
    red = tmp_path / "red.json"
    red.write_text(json.dumps({"Quinacridone red": 90, WHITE: 10}))
    names = [*NEUTRALS[1:5], "red", "yellow"]
    primers = write_primers(tmp_path / "primers.cxf", names, shine={"yellow": 0.5})
    done = cli("hiding", red, "--primers", primers, "--json")
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    paint = report["paints"][0]
    assert paint["best_primer"] == "red" and report["primers_file"] == str(primers)
    said = {p["primer"]: p for p in paint["primers"]}
    assert list(said) == names and said["red"]["coats"] == 1
    assert said["red"]["lab"] == pytest.approx(reflectance_to_Lab(OHTA["red"]), abs=0.01)
    assert any("'yellow' reads like no matte primer" in n for n in report["notes"])
    assert not any("'red'" in n for n in report["notes"])
    shown = cli("hiding", red, "--primers", primers)
    assert "over each primer of" in shown.stdout and "red ←" in shown.stdout
    matched = cli("match", "--example", "--primers", primers)
    assert matched.returncode == 0, matched.stderr
    assert f"of {primers} (L*" in " ".join(matched.stdout.split())
    at_15 = tuple(g for g in GEOMETRIES if g.name != FACE_GEOMETRY)
    refused = {
        "sample 'red': no reading at 45as45": write_primers(tmp_path / "no45.cxf", ["red"], at_15),
        "of sample 'red' appears twice": write_primers(tmp_path / "twice.csv", ["red", "red"]),
    }  # fmt: skip
    for message, path in refused.items():
        done = cli("hiding", red, "--primers", path)
        assert done.returncode == 2 and message in " ".join(done.stderr.split()), done.stderr
        assert str(path) in done.stderr
    harness = cli("match", "evaluate", "--targets", "1", "--primers", primers)
    assert harness.returncode == 2 and "--primers" in harness.stderr
    monkeypatch.setenv("FLAKELAB_PRIMERS", str(primers))
    workplace = json.loads(cli("hiding", red, "--json").stdout)
    assert workplace["primers_file"] == str(primers)
    assert workplace["paints"][0]["best_primer"] == "red"
    greys = write_primers(tmp_path / "greys.cxf", NEUTRALS[1:5])
    given = json.loads(cli("hiding", red, "--primers", greys, "--json").stdout)
    assert given["primers_file"] == str(greys) and given["paints"][0]["best_primer"] in NEUTRALS
    monkeypatch.setenv("FLAKELAB_PRIMERS", str(tmp_path / "gone.cxf"))
    gone = cli("hiding", red)
    assert gone.returncode == 2 and "FLAKELAB_PRIMERS:" in gone.stderr and "gone.cxf" in gone.stderr


def test_match_names_the_primer_for_each_candidate_as_hiding_does(tmp_path, cli):
    """``match --example``: each candidate carries the grey to spray it over and its coats,
    and its weighed recipe, read by ``flakelab hiding``, gets the same grey and coats."""
    best = tmp_path / "best.json"
    done = cli("match", "--example", "--recipe-out", best, "--json")
    assert done.returncode == 0, done.stderr
    candidate = json.loads(done.stdout)["candidates"][0]["hiding"]
    assert candidate["best_primer"] in GREY_SHADES and candidate["coats"] >= 1
    read = cli("hiding", best, "--json")
    assert read.returncode == 0, read.stderr
    paint = json.loads(read.stdout)["paints"][0]
    assert (paint["best_primer"], paint["coats"]) == (candidate["best_primer"], candidate["coats"])
    shown = cli("match", "--example")
    assert f"spray over grey {candidate['best_primer']}" in shown.stdout


def test_match_keeps_a_transparent_candidate_on_the_primer_it_was_predicted_over(library):
    """A candidate that hides nothing (a quinacridone red masstone) looks as predicted only
    over what the cases were sprayed over: its primer line names the library's primer (L* 16
    read bare) and the nominal build, not a ground of the colorist's choosing; one that hides
    gets its grey."""
    from types import SimpleNamespace

    from flakelab.cli.match import _add_hiding, _hiding_text

    recipes = [{"Quinacridone red": 1.0}, {"Iron oxide red": 1.0}]
    candidates = [SimpleNamespace(fractions=r) for r in recipes]
    report = {"candidates": [{}, {}]}
    _add_hiding(report, candidates, library, ("45as15", "45as45", "45as110"))
    clear, hiding_one = (entry["hiding"] for entry in report["candidates"])
    assert clear["best_primer"] is None and clear["library_primer_lightness"] == pytest.approx(
        15.94, abs=0.01
    )
    said = _hiding_text(clear)
    assert "predicted over the library's primer (L* 16) at 15 µm" in said
    assert hiding_one["best_primer"] in GREY_SHADES
    assert _hiding_text(hiding_one).startswith(
        f"primer: spray over grey {hiding_one['best_primer']}"
    )
