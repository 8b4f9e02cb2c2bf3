"""Toner library: optics against known values, validation of files and recipes."""

from __future__ import annotations

import json
import re
from dataclasses import replace
from importlib.resources import files

import colour
import numpy as np
import pytest
import torch

from flakelab.core.spectra import WAVELENGTHS
from flakelab.io import read_library, write_library
from flakelab.library import (
    PAINT_FAMILIES,
    AluminiumFlake,
    Library,
    LibraryError,
    aluminium_refractive_index,
    flake_reflectance,
    fresnel_reflectance,
    pearl_reflectance,
)
from flakelab.models.network import ModelError


def test_aluminium_reflectance_in_air_matches_handbook_values():
    n = aluminium_refractive_index(np.array([450.0, 550.0, 650.0, 820.0]))
    R = fresnel_reflectance(1.0, 1.0, n)
    # Aluminium reflects ~91–92 % across the visible with its interband dip near 1.5 eV (~820 nm)
    assert R[:3] == pytest.approx([0.92, 0.915, 0.91], abs=0.01)
    assert R[3] < R[2] - 0.02


def test_fresnel_matches_colour_science_for_dielectrics_and_total_internal_reflection():
    for theta in (0.0, 20.0, 40.0):
        expected = np.mean(
            colour.phenomena.thin_film_tmm([1.0, 1.0, 1.5], 0.0, 550, theta)[0][0, 0, 0]
        )
        assert fresnel_reflectance(np.cos(np.radians(theta)), 1.0, 1.5) == pytest.approx(expected)
    critical = np.degrees(np.arcsin(1 / 1.5))
    assert fresnel_reflectance(np.cos(np.radians(critical + 1)), 1.5, 1.0) == pytest.approx(1.0)


def test_flake_reflectance_is_bounded_and_rises_toward_grazing():
    R = flake_reflectance(np.array([0.0, 45.0, 80.0, 89.0]), WAVELENGTHS)
    assert R.shape == (4, 31) and np.all((R > 0.5) & (R <= 1))
    assert np.all(R[3] > R[2])


def test_pearl_is_lossless_and_its_colour_shifts_blue_with_angle():
    for coating in (60.0, 75.0, 140.0):
        R = pearl_reflectance(coating, WAVELENGTHS, [0.0, 60.0])
        assert np.all((R >= 0) & (R <= 1))
    for coating in (60.0, 75.0):  # first-order peak inside 400–700 nm
        peak = WAVELENGTHS[np.argmax(pearl_reflectance(coating, WAVELENGTHS, [0.0, 60.0]), axis=-1)]
        assert peak[1] < peak[0]  # the interference peak moves to shorter wavelengths off-normal
    # thicker coatings put the first-order peak at longer wavelengths
    first_order = [WAVELENGTHS[np.argmax(pearl_reflectance(c, WAVELENGTHS)[0])] for c in (60, 75)]
    assert first_order[1] > first_order[0]


def test_demo_library_round_trips_and_has_the_families():
    lib = read_library()
    assert lib.synthetic and len(lib.toners) == 35
    assert [len(lib.of_kind(k)) for k in ("aluminium", "pigment", "pearl")] == [10, 20, 5]
    families = {t.family for t in lib.of_kind("pigment")}
    assert {"phthalocyanine", "quinacridone", "perylene", "iron oxide", "carbon"} <= families


def test_a_recipe_is_a_pearl_with_any_pearl_a_solid_without_effect_toners():
    lib = read_library()
    recipes = [
        {"Al medium": 0.8, "Phthalo blue GS": 0.2},
        {"Al medium": 0.3, "Pearl silver white": 0.01, "Quinacridone red": 0.1},
        {"Phthalo blue GS": 0.5, "Carbon black": 0.5},
        {"Pearl silver white": 1.0},
    ]
    x = np.array([lib.fractions(r) for r in recipes])
    assert lib.paint_families(x).tolist() == ["metallic", "pearl", "solid", "pearl"]
    assert set(lib.paint_families(x)) <= set(PAINT_FAMILIES)


def test_library_file_round_trip(tmp_path):
    lib = read_library()
    path = tmp_path / "shop.json"
    write_library(lib, path)
    again = read_library(path)
    assert again.names == lib.names
    np.testing.assert_array_equal(
        again["Phthalo blue GS"].absorption, lib["Phthalo blue GS"].absorption
    )


def test_densities_are_optional_and_a_can_by_volume_names_the_toners_without_one(tmp_path):
    lib = read_library()
    assert lib.densities(["Titanium dioxide white"]) == {"Titanium dioxide white": 1.45}
    data = lib.to_dict()
    for toner in data["toners"][:3]:
        del toner["density_g_ml"]
    path = tmp_path / "shop.json"
    path.write_text(json.dumps(data))
    partial = read_library(path)
    assert partial["Al fine bright"].density_g_ml is None
    assert partial.densities(["Carbon black"]) == {"Carbon black": 0.97}
    with pytest.raises(LibraryError, match="no density_g_ml for Al fine bright, Al fine dark, so"):
        partial.densities(["Al fine bright", "Carbon black", "Al fine dark"])
    write_library(partial, path)  # what is not given is not written as null
    assert "density_g_ml" not in json.loads(path.read_text())["toners"][0]
    assert read_library(path)["Carbon black"].density_g_ml == 0.97


def test_recipe_validation():
    lib = read_library()
    f = lib.fractions({"Al coarse": 60.0, "Phthalo blue GS": 40.0}, total=100.0)
    assert f.sum() == pytest.approx(1) and f[lib.names.index("Al coarse")] == pytest.approx(0.6)
    with pytest.raises(LibraryError, match="unknown toner 'Al cosmic'"):
        lib.fractions({"Al cosmic": 1.0})
    with pytest.raises(LibraryError, match="Al coarse: expected a non-negative amount, got -1"):
        lib.fractions({"Al coarse": -1.0})
    with pytest.raises(LibraryError, match="amounts sum to 90, expected the can's 100"):
        lib.fractions({"Al coarse": 50.0, "Phthalo blue GS": 40.0}, total=100.0)


def test_a_toner_name_refused_names_the_one_it_likely_means():
    """A name typed in lower case, or copied from a spreadsheet with a non-breaking space,
    is refused naming the toner it means: the spelling alone was compared, case and all, and
    both were refused without a hint. A misspelling is named as before; a name like none, not
    at all."""
    from flakelab.library import did_you_mean

    lib = read_library()
    for typed, meant in (
        ("phthalo blue gs", "Phthalo blue GS"),
        ("Al\xa0medium", "Al medium"),
        ("  carbon  BLACK ", "Carbon black"),
        ("Carbon blak", "Carbon black"),
    ):
        assert did_you_mean(typed, lib.names) == f" (did you mean {meant!r}?)", typed
        with pytest.raises(LibraryError, match=re.escape(f"(did you mean {meant!r}?)")):
            lib.fractions({typed: 1.0})
        with pytest.raises(LibraryError, match=re.escape(f"(did you mean {meant!r}?)")):
            lib[typed]  # noqa: B018
    assert did_you_mean("Quinacridone gold", ["Al medium", "Carbon black"]) == ""


def test_library_file_with_missing_spectrum_or_bad_field_is_rejected(tmp_path):
    data = read_library().to_dict()
    del data["toners"][12]["absorption"]
    path = tmp_path / "broken.json"
    path.write_text(json.dumps(data))
    with pytest.raises(LibraryError, match=r"toners\[12\] .*missing fields \['absorption'\]"):
        read_library(path)
    data = read_library().to_dict()
    data["toners"][0]["radius_um"] = -5
    path.write_text(json.dumps(data))
    with pytest.raises(LibraryError, match="Al fine bright: radius_um: expected a positive number"):
        read_library(path)
    data["toners"][0]["radius_um"] = 5
    data["toners"][15]["absorption"] = data["toners"][15]["absorption"][:30]
    path.write_text(json.dumps(data))
    with pytest.raises(LibraryError, match=r"absorption: expected 31 numbers .*, got 30 values"):
        read_library(path)


def _setting(*keys, value):
    """An edit of a library file's structure: the item at ``keys`` set to ``value``."""

    def edit(data):
        for key in keys[:-1]:
            data = data[key]
        data[keys[-1]] = value

    return edit


def test_a_library_file_s_every_flaw_names_the_file(tmp_path):
    good = read_library().to_dict()
    path = tmp_path / "shop.json"
    flawed = {  # before: the first two internal errors, the third unnamed, names 5 and "" read
        "toners: expected a list of toner objects": lambda d: d.update(toners={"a": 1}),
        "toners: expected a list of toner objects ": lambda d: d["toners"].append(5),
        "wavelengths: expected 400–700 nm in 10 nm steps": lambda d: d.update(wavelengths="abc"),
        "binder: expected an object": lambda d: d.update(binder=[1]),
        "toners[0] (5): name: expected a text, got 5": lambda d: d["toners"][0].update(name=5),
        "toners[0] (): name: expected a text, got ''": lambda d: d["toners"][0].update(name=""),
        "binder: unknown fields ['colour']": lambda d: d["binder"].update(colour=1),
        "binder: refractive_index: expected ≥ 1": lambda d: d["binder"].update(
            refractive_index=0.5
        ),
        "toner names appear twice: ['Al fine bright']": lambda d: d["toners"].append(
            d["toners"][0]
        ),
        "expected at least one toner": lambda d: d.update(toners=[]),
        # before: an internal error (unhashable type), then messages that named no field
        "toners[0] (Al fine bright): kind: expected one of aluminium, pigment, pearl, got {}": (
            _setting("toners", 0, "kind", value={})
        ),
        "Quinacridone magenta: absorption, 420 nm: expected a number, got 'x'": (
            _setting("toners", 15, "absorption", 2, value="x")
        ),
        "Quinacridone magenta: g: expected a value in (−1, 1), got 'x'": (
            _setting("toners", 15, "g", value="x")
        ),
        "Quinacridone magenta: family: expected a text, got {}": (
            _setting("toners", 15, "family", value={})
        ),
        "binder: primer_reflectance, 690 nm: expected a number, got []": (
            _setting("binder", "primer_reflectance", 29, value=[])
        ),
        # before: accepted, and the physics' prediction came out NaN
        "Quinacridone magenta: absorption, 690 nm: expected a value from 0 to 10000, got 1e+308": (
            _setting("toners", 15, "absorption", 29, value=1e308)
        ),
        # before: accepted, and the physics warned, came out NaN or counted infinite glints
        "Al fine bright: orientation_sd_deg: expected at least 1.0, got 1e-320": (
            _setting("toners", 0, "orientation_sd_deg", value=1e-320)
        ),
        "Al fine bright: thickness_um: expected at least 0.01, got 1e-300": (
            _setting("toners", 0, "thickness_um", value=1e-300)
        ),
        "Pearl silver white: radius_um: expected at least 1.0, got 1e-12": (
            _setting("toners", 30, "radius_um", value=1e-12)
        ),
        # a density in g/L where g/mL is meant would weigh a litre as a tonne
        "Carbon black: density_g_ml: expected at most 5.0, got 970": (
            _setting("toners", 28, "density_g_ml", value=970)
        ),
        "Carbon black: density_g_ml: expected a positive number, got '0.97'": (
            _setting("toners", 28, "density_g_ml", value="0.97")
        ),
    }
    for message, edit in flawed.items():
        data = json.loads(json.dumps(good))
        edit(data)
        path.write_text(json.dumps(data))
        with pytest.raises(LibraryError) as raised:
            read_library(path)
        assert str(raised.value).startswith(f"{path}: ") and message.strip() in str(raised.value)


def test_a_library_of_another_model_is_refused_and_says_how():
    """A model that knows under half of a library's toners was trained for another one."""
    from flakelab.match.models import forward_for
    from flakelab.models.registry import shipped_model

    library, model = read_library(), shipped_model("five-angle")
    renamed = Library("renamed", tuple(replace(t, name=f"{t.name} 2") for t in library.toners))
    with pytest.raises(ModelError, match=r"35 of the library's are not in the model .*; 35 of"):
        forward_for(model, renamed)


def test_a_toner_added_to_the_library_after_training_is_a_new_toner():
    """A toner the model was not trained with (a paint maker's new one, added to the shop's
    library) is predicted as a new toner, through the hybrid, with a note naming it; a toner
    the library lacks is never used, and the library's order is its own. Before, each was
    refused: "train a model for this library". An added copy of a known toner predicts what
    the known one predicts (the physics ratio between the two is one); the library without
    a toner, or reversed, predicts what the full library does for the same recipe."""
    from flakelab.errors import Note
    from flakelab.match.forward import HybridForward
    from flakelab.match.models import forward_for
    from flakelab.models.registry import shipped_model

    library, model = read_library(), shipped_model("five-angle")
    full = forward_for(model, library)
    blue = library.toners[library.names.index("Phthalo blue GS")]
    added = Library("added", (*library.toners, replace(blue, name="Phthalo blue GS 2025")))
    with pytest.warns(Note, match=r"1 toner\(s\) the model demo-five-angle was not trained "
                      r"with.*'Phthalo blue GS 2025'"):  # fmt: skip
        hybrid = forward_for(model, added)
    assert isinstance(hybrid, HybridForward) and "Phthalo blue GS 2025" in hybrid.novel
    assert "Phthalo blue GS 2025 (as Phthalo blue GS)" in hybrid.name_for(["Phthalo blue GS 2025"])
    rng = np.random.default_rng(5)
    x = rng.dirichlet(np.ones(4), size=6)  # aluminium, blue, maroon, violet
    blue = rng.uniform(0.01, 0.25, size=6)  # under the 30 % where the physics base leads
    x = np.insert(np.delete(x, 1, axis=1), 1, 0.0, axis=1)
    x = x / x.sum(1, keepdims=True) * (1 - blue[:, None])
    x[:, 1] = blue
    chosen = ["Al medium", "Phthalo blue GS", "Perylene maroon", "Quinacridone violet"]

    def predicted(forward, names):
        fractions = np.zeros((len(x), len(forward.toners)))
        fractions[:, [forward.toners.index(n) for n in names]] = x
        with torch.no_grad():
            return forward(torch.as_tensor(fractions, dtype=forward.dtype))[0].double().numpy()

    known = predicted(full, chosen)
    as_new = predicted(hybrid, ["Al medium", "Phthalo blue GS 2025", *chosen[2:]])
    np.testing.assert_allclose(as_new, known, rtol=1e-4)
    typo = Library(
        "typo", tuple(replace(t, name=t.name.replace("GS", "G S")) for t in library.toners)
    )
    with pytest.warns(Note, match=r"'Phthalo blue G S' \(did you mean 'Phthalo blue GS'\?\)"):
        forward_for(model, typo)
    for other in (
        Library("no Al VMP", tuple(t for t in library.toners if t.name != "Al VMP")),
        Library("reversed", library.toners[::-1]),
    ):
        forward = forward_for(model, other)
        assert forward.toners == other.names
        np.testing.assert_allclose(predicted(forward, chosen), known, rtol=1e-5)


def test_duplicate_toner_names_rejected():
    with pytest.raises(LibraryError, match="appear twice"):
        Library("x", (AluminiumFlake("A", 5, 0.2, 10), AluminiumFlake("A", 6, 0.2, 10)))


def test_the_demo_white_is_a_rutile_white(pigment_km):
    """The demo library's titanium dioxide against two measurements of real rutile whites: its
    K/S within × 2.5 of Okumura's titanium white at 400–440 nm, its band edge, and the world's
    white masstone at 45as45 within 1.5 in a*, b* of Golden's titanium white masstone (an
    independent reflectance). Its edge at 410 nm until stop 52 read 8–18 × Okumura's K/S at
    410–430 nm, and a cream: a* −5.0, b* +8.1 against Golden's −1.0, +2.4."""
    from flakelab.cases.generator import World
    from flakelab.core.colorimetry import reflectance_to_Lab

    library = read_library()
    white = library["Titanium dioxide white"]
    okumura = pigment_km("okumura_okumura.rs", first_nm=360, spectra=2)["Titanium White"]
    edge = slice(0, 5)
    ratio = (white.absorption / white.scattering)[edge] / (okumura[:31] / okumura[31:])[edge]
    assert np.all((ratio > 1 / 2.5) & (ratio < 2.5)), ratio

    world = World(library)
    x = np.array([[t.name == white.name for t in library.toners]], dtype=float)
    R, _ = world.appearance(x, world.nominal(1))
    at_45 = [g.name for g in world.geometries].index("45as45")
    lab = reflectance_to_Lab(R[0, at_45])
    golden = pigment_km("cmt_Golden_HB.rs", first_nm=380)["1380-Titanium White - Tr2 (P.W. 6)"]
    assert np.hypot(*(lab[1:] - reflectance_to_Lab(golden)[1:])) < 1.5
    assert lab[0] > 90


def test_library_show_says_how_the_model_knows_each_toner(tmp_path, cli):
    """'flakelab library show': the demo's two new toners stand in as the transparent iron
    oxides (as docs/toner-library.md says), every other toner learned from the cases its
    model's record gives; a toner added to a library since is "added", standing in as its
    nearest known toner (an exact copy: as the original), and a toner the library lacks is
    named."""
    from flakelab.models.registry import shipped_model

    report = json.loads(cli("library", "show", "--json").stdout)
    counts = shipped_model("five-angle").info["toner_cases"]
    standing = {r["toner"]: (r["standing"], r["stands_in_as"]) for r in report["toners"]}
    assert standing.pop("Perylene red") == ("new", "Transparent iron oxide red")
    assert standing.pop("Isoindoline yellow") == ("new", "Transparent iron oxide yellow")
    assert set(standing.values()) == {("learned", None)}
    assert all(r["cases"] == counts[r["toner"]] for r in report["toners"])
    data = json.loads((files("flakelab.data") / "demo-library.json").read_text())
    blue = next(t for t in data["toners"] if t["name"] == "Phthalo blue GS")
    data["toners"] = [t for t in data["toners"] if t["name"] != "Al VMP"]
    data["toners"].append({**blue, "name": "Phthalo blue 2026"})
    path = tmp_path / "shop.json"
    path.write_text(json.dumps(data))
    shown = cli("library", "show", path)
    assert shown.returncode == 0, shown.stderr
    assert re.search(r"Phthalo blue 2026 .* 0 +added: as Phthalo blue GS", shown.stdout)
    assert "the model's toners the library lacks (never used): Al VMP" in shown.stderr
    path.write_text(json.dumps(data)[:-40])
    broken = cli("library", "show", path)
    assert broken.returncode == 2 and str(path) in broken.stderr
