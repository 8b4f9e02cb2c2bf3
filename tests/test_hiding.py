"""How thick a basecoat must be to hide the primer, and over which grey
(:mod:`flakelab.physics.hiding`, ``flakelab hiding``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from flakelab.core.geometry import instrument_geometries
from flakelab.io import read_library
from flakelab.physics.hiding import BUILD_GRID, GREY_SHADES, hiding
from flakelab.physics.hiding import _where_it_falls_to as where_it_falls_to

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
    sooner the more white it holds (38 µm at 2 %, 2.7 µm at 40 %)."""
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
    (L* 77, nearest G3) goes over G1, white, over which it comes to its full colour in three
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
