"""The colour codes a shop has painted, and a code's variants (flakelab.cases.variants)."""

from __future__ import annotations

import itertools
import json
from dataclasses import replace
from datetime import UTC, datetime, timedelta

import numpy as np
import pytest

from flakelab.cases.case import Case, CaseError
from flakelab.cases.database import add_cases, code_summary, open_database, shop_summary
from flakelab.cases.exchange import write_cases
from flakelab.cases.generator import World
from flakelab.cases.variants import colour_variants
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.core.spectra import WAVELENGTHS
from flakelab.core.tolerance import tolerance_preset
from flakelab.io import read_library

TOLERANCE = tolerance_preset("refinish")
START = datetime(2026, 3, 2, 8, 0, tzinfo=UTC)


@pytest.fixture(scope="module")
def generated() -> list[Case]:
    world = World(read_library(None), "five-angle")
    return [c for batch in world.cases(12, seed=7, batch=12) for c in batch]


def _cars(generated: list[Case], lightness: list[float], sprayed: list[float], code: str):
    """Cars of one ``code``: the first generated car's colour with its reflectance scaled by
    each of ``lightness`` (lighter above 1), each sprayed with another generated case's recipe
    and a spray-out scaled by ``sprayed`` from its car, a day apart, accepted in shop 'south'."""
    base = generated[0]
    return [
        replace(
            generated[k + 1],
            case_id=f"{code}-{k}",
            target=base.target * scale,
            sprayout=base.target * scale * off,
            colour_code=code,
            shop="south",
            outcome="accepted",
            created_at=START + timedelta(days=k),
        )
        for k, (scale, off) in enumerate(zip(lightness, sprayed, strict=True))
    ]


def _worst_share(a: Case, b: Case) -> float:
    """The worst geometry's share of the limit between two cars, either way round: one pair
    at a time, as the tolerance judges a spray-out."""
    names = a.geometry_names
    la, lb = reflectance_to_Lab(a.target), reflectance_to_Lab(b.target)
    shares = []
    for ref, smp in ((la, lb), (lb, la)):
        de00, dLCH, _ = TOLERANCE.judge(names, ref, smp)
        shares.append(TOLERANCE.share_of_limit(names, de00=de00, dLCH=dLCH).max())
    return float(max(shares))


def test_variants_cover_the_cars_each_within_the_tolerance_of_its_centre(generated):
    """Five cars of the code's usual colour and three a tenth lighter (another plant's): two
    variants, the usual one first; its offset is the lighter one's ΔL* > 0 and well outside
    the tolerance; every car lies within it of its variant's centre, the car whose furthest
    member lies nearest; each variant's recipe is the case whose spray-out lies nearest its
    centre car, found one case at a time."""
    usual = [1.0, 1.004, 0.996, 1.002, 0.998]
    lighter = [1.10, 1.104, 1.097]
    sprayed = [1.03, 0.99, 1.05, 1.012, 0.97, 1.04, 1.006, 0.95]
    cars = _cars(generated, usual + lighter, sprayed, "TOYOTA 1G3")
    variants = colour_variants(cars, TOLERANCE)
    assert [sorted(c.case_id for c in v.cases) for v in variants] == [
        [f"TOYOTA 1G3-{k}" for k in range(5)],
        [f"TOYOTA 1G3-{k}" for k in range(5, 8)],
    ]
    main, other = variants
    assert [c.case_id for c in other.cases] == ["TOYOTA 1G3-7", "TOYOTA 1G3-6", "TOYOTA 1G3-5"]
    assert np.all(main.offset_de00 == 0) and other.offset_de00.max() > 2
    assert np.all(other.offset_dLCH[:, 0] > 0)  # lighter at every geometry
    assert set(main.offset_texture.values()) == {0.0} and "G" in other.offset_texture
    for name, value in other.offset_texture.items():
        assert value == other.centre.target_texture[name] - main.centre.target_texture[name]
    for variant in variants:
        members = variant.cases
        furthest = {c.case_id: max(_worst_share(c, o) for o in members) for c in members}
        assert variant.spread == pytest.approx(furthest[variant.centre.case_id])
        assert variant.spread == pytest.approx(min(furthest.values())) and variant.spread <= 1
        nearest = min(members, key=lambda c: _sprayout_share(variant.centre, c))
        assert variant.recipe.case.case_id == nearest.case_id
        assert dict(variant.recipe.case.recipe) == dict(nearest.recipe)
    assert main.centre.case_id == "TOYOTA 1G3-0"  # the middle of the usual five
    assert main.recipe.case.case_id == "TOYOTA 1G3-1"  # 0.99: the nearest spray-out
    assert other.recipe.case.case_id == "TOYOTA 1G3-6"


def _sprayout_share(car: Case, case: Case) -> float:
    names = car.geometry_names
    de00, dLCH, _ = TOLERANCE.judge(
        names, reflectance_to_Lab(car.target), reflectance_to_Lab(case.sprayout)
    )
    return float(TOLERANCE.share_of_limit(names, de00=de00, dLCH=dLCH).max())


def test_a_chain_of_near_cars_needs_as_few_variants_as_cover_it(generated):
    """Cars each a little lighter than the one before: every neighbour within the tolerance
    of the next, the ends far outside it. The variants hold every car once, each within
    ``within`` of its centre; no fewer centres would cover the chain (every choice of one
    fewer tried); a wider reach never needs more variants."""
    steps = [1.0 + 0.02 * k for k in range(7)]
    cars = _cars(generated, steps, [1.0] * len(steps), "NH731P")
    assert all(_worst_share(a, b) < 1 for a, b in itertools.pairwise(cars))
    assert _worst_share(cars[0], cars[-1]) > 2
    counts = []
    for within in (0.3, 0.5, 1.0, 3.0):
        variants = colour_variants(cars, TOLERANCE, within)
        assert sorted(c.case_id for v in variants for c in v.cases) == sorted(
            c.case_id for c in cars
        )
        for variant in variants:
            assert all(_worst_share(variant.centre, c) <= within for c in variant.cases)
        fewer = itertools.combinations(cars, len(variants) - 1)
        assert not any(
            all(
                min((_worst_share(c, o) for o in centres), default=2 * within) <= within
                for c in cars
            )
            for centres in fewer
        ), within
        counts.append(len(variants))
    assert counts == sorted(counts, reverse=True) and counts[-1] == 1 and counts[2] == 2
    assert len(colour_variants(cars[:1], TOLERANCE)) == 1
    with pytest.raises(CaseError, match="within: expected a share"):
        colour_variants(cars, TOLERANCE, 0.0)
    with pytest.raises(CaseError, match="no cases"):
        colour_variants([], TOLERANCE)


def _cover_at_once(shares: np.ndarray, within: float) -> list[int]:
    """The greedy cover as first written, every count over the whole matrix at once."""
    reach, left, centres = shares <= within, np.ones(len(shares), dtype=bool), []
    while left.any():
        gain = (reach & left).sum(axis=1)
        nearness = np.where(reach & left, shares, 0.0).sum(axis=1)
        best = np.flatnonzero(gain == gain.max())
        centres.append(int(best[np.argmin(nearness[best])]))
        left &= ~reach[centres[-1]]
    return centres


def test_the_cover_in_blocks_is_the_cover_at_once(monkeypatch):
    """Judged in blocks of a few pairs, as a code of thousands of cars is, every pair is
    judged once and told to the progress, the reach is the whole matrix's, and the cover, the
    chip nearest each car and each group's centre are the ones the whole matrix of shares at
    once gives, ties broken the same, though only the pairs within reach are kept and the
    shares are judged again where needed."""
    from flakelab.cases import variants

    rng = np.random.default_rng(2)
    Lab = rng.normal([60.0, 0.0, 0.0], [0.4, 0.25, 0.25], (70, 5, 3))
    names = ("45as15", "45as25", "45as45", "45as75", "45as110")
    whole = variants.worst_shares(Lab, Lab, names, TOLERANCE)
    monkeypatch.setattr(variants, "PAIRS_AT_ONCE", 150)  # two rows at once

    def shares_of(rows, columns):
        assert len(rows) * len(columns) <= 2 * max(150, len(columns))  # in blocks of about 150
        return variants.worst_shares(Lab[rows], Lab[columns], names, TOLERANCE)

    for within in (0.7, 0.8, 1.0, 1.2):  # 26, 14, 4 and 2 centres
        told: list[int] = []
        reach = variants.pairwise_reach(Lab, names, TOLERANCE, within, told.append)
        assert len(told) == 35 and sum(told) == 70 * 71 // 2
        np.testing.assert_array_equal(reach, whole <= within)
        found = variants.covering_centres(reach, shares_of)
        assert found == _cover_at_once(whole, within) and 1 < len(found) < 70
        nearest = variants._nearest_chip(70, found, shares_of)
        np.testing.assert_array_equal(nearest, np.argmin(whole[:, found], axis=1))
        for k in range(len(found)):
            group = np.flatnonzero(nearest == k)
            furthest = whole[np.ix_(group, group)].max(axis=1)
            centre, spread = variants._centre(group, reach, shares_of)
            assert centre == group[np.argmin(furthest)]
            assert spread == pytest.approx(furthest.min(), rel=1e-12)
    # a group that no car of it reaches whole (its chip gone to a chip alike) is judged whole
    group = np.array([3, 17, 40])
    reach = variants.pairwise_reach(Lab, names, TOLERANCE, 0.7)
    assert not reach[np.ix_(group, group)].all(axis=1).any()
    furthest = whole[np.ix_(group, group)].max(axis=1)
    centre, spread = variants._centre(group, reach, shares_of)
    assert (centre, spread) == (group[np.argmin(furthest)], pytest.approx(furthest.min()))


def test_code_summary_counts_each_codes_cases_in_the_database(generated, database_url):
    """The database counts each code's cases by outcome, and the shops that made them, one
    shop's or all; cases without a code are not a code; the shops' summary is what it was."""
    cars = _cars(generated, [1.0, 1.01, 1.1, 1.0], [1.0] * 4, "TOYOTA 1G3")
    cars[1] = replace(cars[1], outcome="corrected", shop="north")
    cars[2] = replace(cars[2], colour_code="NH731P", shop="north")
    cars[3] = replace(cars[3], colour_code="")
    engine = open_database(database_url)
    add_cases(engine, cars)
    summary = {
        s["colour_code"]: (s["cases"], s["outcomes"], s["shops"]) for s in code_summary(engine)
    }
    assert summary == {
        "NH731P": (1, {"accepted": 1}, 1),
        "TOYOTA 1G3": (2, {"accepted": 1, "corrected": 1}, 2),
    }
    north = {s["colour_code"]: (s["cases"], s["shops"]) for s in code_summary(engine, shop="north")}
    assert north == {"NH731P": (1, 1), "TOYOTA 1G3": (1, 1)}
    assert [s["last"] for s in code_summary(engine) if s["colour_code"] == "TOYOTA 1G3"] == [
        START + timedelta(days=1)
    ]
    assert {s["shop"]: s["cases"] for s in shop_summary(engine)} == {"north": 2, "south": 2}


def test_cases_codes_and_variants_on_the_command_line(generated, tmp_path, cli):
    """'cases codes' lists the codes; 'cases variants CODE' finds the variants in a database
    and in a case file alike, the code typed as on the plate, of the cars since a date where
    asked; a code the shop lacks is refused with the one it likely means, and nothing is
    written; --plot draws them, and a figure file of no known format is refused before any
    work. --car names the variant the car in the booth lies nearest, or says none is its
    colour."""
    usual, lighter = [1.0, 1.004, 0.996], [1.10, 1.104]
    cars = _cars(generated, usual + lighter, [1.01, 0.99, 1.0, 1.02, 1.0], "Toyota 1G3")
    db, csv = tmp_path / "shop.db", tmp_path / "cases.csv"
    add_cases(open_database(str(db)), cars)
    write_cases(cars, csv)
    for source in (db, csv):
        listed = cli("cases", "codes", "-d", source, "--json")
        assert listed.returncode == 0, listed.stderr
        assert [(c["colour_code"], c["cases"]) for c in json.loads(listed.stdout)["codes"]] == [
            ("TOYOTA 1G3", 5)
        ]
    for source in (db, csv):
        found = cli("cases", "variants", "toyota 1g3", "-d", source, "--json")
        assert found.returncode == 0, found.stderr
        report = json.loads(found.stdout)
        assert report["colour_code"] == "TOYOTA 1G3" and report["cars"] == 5
        assert [v["cases"] for v in report["variants"]] == [3, 2]
        assert report["variants"][1]["offset_dLCH"]["dL"] > 0
    # the cars a day apart from 08:00 UTC: --since (local time, to the minute as a report
    # shows a time; refused before) keeps the last three
    recent = cli("cases", "variants", "1G3", "-d", db, "--since", "2026-03-03T20:00", "--json")
    assert json.loads(recent.stdout)["cars"] == 3
    from flakelab.core.measurement import Measurement
    from flakelab.io import write_measurements

    booth = {"lighter": 1.101, "darker": 0.8}
    for sample, scale in booth.items():
        reading = Measurement(sample, cars[0].geometries, WAVELENGTHS, cars[0].target * scale)
        write_measurements([reading], tmp_path / f"{sample}.cxf")
    found = json.loads(cli("cases", "variants", "1G3", "-d", db, "--car", tmp_path / "lighter.cxf",
                           "--json").stdout)  # fmt: skip
    assert found["car"]["nearest_variant"] == 2 and found["car"]["within_tolerance"]
    assert [v["car"]["passes"] for v in found["variants"]] == [False, True]
    darker = cli("cases", "variants", "1G3", "-d", db, "--car", tmp_path / "darker.cxf")
    assert "no variant the shop has painted is this car's colour" in " ".join(darker.stdout.split())
    fewer = Measurement("door", cars[0].geometries[:3], WAVELENGTHS, cars[0].target[:3])
    write_measurements([fewer], tmp_path / "door.cxf")
    unread = cli("cases", "variants", "1G3", "-d", db, "--car", tmp_path / "door.cxf")
    assert unread.returncode == 2 and "door.cxf: not read at 45as75, 45as110" in unread.stderr
    figure = tmp_path / "variants.png"
    shown = cli("cases", "variants", "1G3", "-d", db, "--plot", figure)
    assert shown.returncode == 0 and "2 variants among 5 cars" in shown.stdout
    assert "comparing 5 cars pair by pair: 15/15 (100 %)" in shown.stderr
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    unknown = cli("cases", "variants", "1G3", "-d", db, "--plot", tmp_path / "variants.txt")
    assert unknown.returncode == 2 and "expected a figure file" in unknown.stderr
    before = db.read_bytes()
    wrong = cli("cases", "variants", "Toyota 1G 3", "-d", db)
    assert wrong.returncode == 2 and "Traceback" not in wrong.stderr
    assert "no cases from any shop of colour code 'TOYOTA 1G 3'" in wrong.stderr
    assert "(did you mean 'TOYOTA 1G3'?)" in wrong.stderr
    for within in ("0", "inf"):
        bad = cli("cases", "variants", "1G3", "-d", db, "--within", within)
        assert bad.returncode == 2 and "--within: expected a share" in bad.stderr
    assert db.read_bytes() == before


def test_variant_chips_are_the_centre_cars_read_back_as_standards(generated, tmp_path, cli):
    """'cases variants --out' writes each variant's centre car as a sample 'CODE #k': read
    back from CxF3 and CSV it is that car's reading, CxF3 keeps the cars and recipe it stands
    for, and 'compare' against a chip finds the car's ΔE00 that --car reports (against the
    deck, --nearest, the chip --car names nearest); a chip held as the car is its own
    variant, and the command suggested next reads that chip in that database; an output of
    no known format, or the database itself, is refused before any work."""
    cars = _cars(generated, [1.0, 1.004, 0.996, 1.10, 1.104], [1.01, 0.99, 1.0, 1.02, 1.0], "1G3")
    db = tmp_path / "shop.db"
    add_cases(open_database(str(db)), cars)
    before = db.read_bytes()
    from flakelab.core.measurement import Measurement
    from flakelab.io import read_measurements, write_measurements

    write_measurements([Measurement("car", cars[0].geometries, WAVELENGTHS, cars[0].target * 1.1)],
                       tmp_path / "car.cxf")  # fmt: skip
    for chips in (tmp_path / "chips.cxf", tmp_path / "chips.csv"):
        written = cli("cases", "variants", "1G3", "-d", db, "--car", tmp_path / "car.cxf",
                      "--out", chips, "--json")  # fmt: skip
        assert written.returncode == 0, written.stderr
        report = json.loads(written.stdout)
        read = read_measurements(chips)
        assert [m.sample for m in read] == ["1G3 #1", "1G3 #2"]
        by_id = {c.case_id: c for c in cars}
        for chip, variant in zip(read, report["variants"], strict=True):
            np.testing.assert_allclose(chip.reflectance, by_id[variant["centre_case_id"]].target,
                                       atol=5e-6)  # fmt: skip
    meta = read_measurements(tmp_path / "chips.cxf")[1].metadata
    lighter = report["variants"][1]
    assert meta["cars"] == "2" and meta["centre_case_id"] == lighter["centre_case_id"]
    assert json.loads(meta["recipe"]) == by_id[lighter["recipe"]["case_id"]].recipe
    judged = cli("compare", tmp_path / "chips.cxf", tmp_path / "car.cxf", "--reference-sample",
                 "1G3 #2", "--json")  # fmt: skip
    worst = max(g["de00"] for g in json.loads(judged.stdout)["geometries"])
    assert worst == pytest.approx(lighter["car"]["de00_max"], abs=2e-3)
    ranked = json.loads(cli("compare", tmp_path / "chips.cxf", tmp_path / "car.cxf", "--nearest",
                            "5", "--json").stdout)  # fmt: skip
    assert [r["reference"] for r in ranked["nearest_references"]] == ["1G3 #2", "1G3 #1"]
    assert ranked["reference"] == "1G3 #2" and ranked["de00_max"] == pytest.approx(worst)
    both = cli("compare", tmp_path / "chips.cxf", tmp_path / "car.cxf", "--nearest", "1",
               "--reference-sample", "1G3 #1")  # fmt: skip
    assert both.returncode == 2 and "not with --reference-sample" in both.stderr
    chip = cli("cases", "variants", "1G3", "-d", db, "--car", tmp_path / "chips.cxf", "--sample",
               "1G3 #2")  # fmt: skip
    said = " ".join(chip.stdout.split())
    assert "1G3 #2 lies nearest variant #2: worst ΔE00 0.00" in said
    assert f"cases nearest {tmp_path / 'chips.cxf'} --sample '1G3 #2' -d {db} --colour-code" in said
    unknown = cli("cases", "variants", "1G3", "-d", db, "--out", tmp_path / "chips.txt2")
    assert unknown.returncode == 2 and "unknown output extension '.txt2'" in unknown.stderr
    itself = cli("cases", "variants", "1G3", "-d", db, "--out", db)
    assert itself.returncode == 2 and "Traceback" not in itself.stderr
    assert db.read_bytes() == before


def test_match_with_a_colour_code_names_the_variant_the_car_lies_nearest(generated, tmp_path,
                                                                         cli):  # fmt: skip
    """'match --colour-code' says which of the code's variants the car lies nearest, as
    'cases variants --car' finds it."""
    cars = _cars(generated, [1.0, 1.004, 0.996, 1.10, 1.104], [1.01, 0.99, 1.0, 1.02, 1.0], "1G3")
    db = tmp_path / "shop.db"
    add_cases(open_database(str(db)), cars)
    from flakelab.core.measurement import Measurement
    from flakelab.io import write_measurements

    car = tmp_path / "car.cxf"
    write_measurements([Measurement("car", cars[0].geometries, WAVELENGTHS, cars[0].target * 1.1)],
                       car)  # fmt: skip
    matched = cli("match", car, "-d", db, "--colour-code", "1g3", "--candidates", "1", "--json")
    assert matched.returncode == 0, matched.stderr
    named = json.loads(matched.stdout)["colour_variant"]
    variants = json.loads(cli("cases", "variants", "1G3", "-d", db, "--car", car, "--json").stdout)
    nearest = variants["variants"][variants["car"]["nearest_variant"] - 1]
    assert named["variant"] == 2 and named["variants"] == 2 and named["cars"] == 2
    assert named["centre_case_id"] == nearest["centre_case_id"]
    assert named["de00_max"] == nearest["car"]["de00_max"] and named["passes"]


def test_a_world_of_colour_codes_paints_each_car_in_one_of_its_colours():
    """With K colour codes every car is one of K OEM colours, met as a popular colour is
    (the first code about 1 / H_K of the cars), its case records the code and its recipe
    that colour's toners; every other draw is the world's without codes (the same case ids),
    and case i's code is the same whatever the batches."""
    from flakelab.cases.generator import ColourCatalogue, WorldSettings

    library = read_library(None)
    plain = [c for b in World(library, "five-angle").cases(1000, seed=7) for c in b]
    world = World(library, "five-angle", WorldSettings(colour_codes=20))
    coded = [c for b in world.cases(1000, seed=7) for c in b]
    assert [c.case_id for c in coded] == [c.case_id for c in plain]
    assert {c.colour_code for c in plain} == {""}
    again = [c for b in world.cases(300, seed=7, batch=16) for c in b]
    assert [c.colour_code for c in again] == [c.colour_code for c in coded[:300]]
    assert all(np.array_equal(a.target, b.target) for a, b in zip(again, coded, strict=False))
    catalogue = ColourCatalogue(world, 7)
    assert catalogue.codes == tuple(f"GEN {k:03d}" for k in range(1, 21))
    share = np.mean([c.colour_code == "GEN 001" for c in coded])
    assert abs(share - 1 / np.sum(1 / np.arange(1, 21))) < 0.05  # 0.278; binomial sd 0.014
    names = library.names
    for case in coded:
        colour = catalogue.formulations[catalogue.codes.index(case.colour_code)]
        assert set(case.recipe) == {names[j] for j in np.flatnonzero(colour > 0)}
    with pytest.raises(ValueError, match="colour_codes: expected a whole number"):
        list(World(library, "five-angle", WorldSettings(colour_codes=-1)).cases(1, seed=0))


def test_cases_generate_records_the_codes_asked_for(tmp_path, cli):
    """'cases generate --colour-codes K' writes each case's code; without, the file has no
    colour code column (as every case file generated before)."""
    from flakelab.cases.exchange import read_cases

    coded, plain = tmp_path / "coded.csv", tmp_path / "plain.csv"
    run = cli("cases", "generate", "--n", "30", "--seed", "2", "--colour-codes", "4", "-o", coded)
    assert run.returncode == 0, run.stderr
    assert {c.colour_code for c in read_cases(coded)} <= {f"GEN 00{k}" for k in range(1, 5)}
    assert cli("cases", "generate", "--n", "30", "--seed", "2", "-o", plain).returncode == 0
    assert "colour_code" in coded.read_text().splitlines()[0]
    assert "colour_code" not in plain.read_text().splitlines()[0]
    assert [c.case_id for c in read_cases(coded)] == [c.case_id for c in read_cases(plain)]


def test_a_code_asked_without_its_numbers_leading_zeros_is_hinted():
    """'gen 2' finds no case of 'GEN 002' (a word matches whole), and is told that code, not
    the nearer spelling 'GEN 029'; 'Toyota 40' is told 'TOYOTA 040'."""
    from flakelab.cases.case import colour_code_hint, has_colour_code

    codes = ["GEN 002", "GEN 029", "TOYOTA 040", "LEXUS 1G3"]
    assert not any(has_colour_code(code, "gen 2") for code in codes)
    assert colour_code_hint("gen 2", codes) == " (did you mean 'GEN 002'?)"
    assert colour_code_hint("Toyota 40", codes) == " (did you mean 'TOYOTA 040'?)"
    assert colour_code_hint("gen 002", codes) == ""


def test_a_chip_of_a_car_known_by_its_lab_alone_is_written_as_it_was_read(generated, tmp_path, cli):
    """A variant whose centre car was read as L*a*b* alone (a case's ``target_recovered``) is
    written as that colour alone: read back, its spectra are recovered and flagged, its
    colour the car's; a JSON chip book, which would give them as measured, is refused and
    nothing is written."""
    from flakelab.io import read_measurements

    cars = _cars(generated, [1.0, 1.004, 1.10], [1.01, 0.99, 1.02], "1G3")
    cars = [replace(c, target_recovered=True) for c in cars]
    db = tmp_path / "shop.db"
    add_cases(open_database(str(db)), cars)
    written = cli("cases", "variants", "1G3", "-d", db, "--out", tmp_path / "chips.cxf", "--json")
    assert written.returncode == 0, written.stderr
    by_id = {c.case_id: c for c in cars}
    chips = read_measurements(tmp_path / "chips.cxf")
    variants = json.loads(written.stdout)["variants"]
    for chip, variant in zip(chips, variants, strict=True):
        assert chip.spectra_recovered
        car = reflectance_to_Lab(by_id[variant["centre_case_id"]].target)
        assert delta_E(chip.lab(), car).max() < 1e-3
    refused = cli("cases", "variants", "1G3", "-d", db, "--out", tmp_path / "chips.json")
    assert refused.returncode == 2 and "Traceback" not in refused.stderr
    assert "recovered from L*a*b*: a json file would give them as measured" in refused.stderr
    assert not (tmp_path / "chips.json").exists()
