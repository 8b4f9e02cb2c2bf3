"""Damage input files at random and feed them to the CLI: every one must be refused in one
line naming the file (exit 2) or read (exit 0), never an internal error (exit 70), a
traceback, a warning or a NaN in the output (the guide's "Bad input" standard).

Each kind starts from a good file made here from the shipped example (or the demo library,
the example recipe, a habits report, a tolerance file, generated cases in CSV and CxF3, a
manifest of instrument files for `cases record-all`, the shipped model, a toner-lot file, the
example calibration panel's reading, a shop's primers) and damages it: an
MA-T12 export by editing its cells, rows, columns and sheets (or cutting its bytes short), one
with camera pictures also by moving a picture or damaging its bytes;
text files by deleting, doubling or cutting lines, replacing numbers and names, inserting
stray characters, or in another encoding (a byte-order mark alone, Windows-1252, a cut
inside a character); JSON files by replacing or deleting one value anywhere in them (a target
for the match and a spray-out for the correction and for `cases record`, half the time, by
values still readable but odd); a model file by editing its description, standardisation or
weights; a shop's SQLite database by replacing one value of one case row (or, for
``database-shops``, of a row of its models, habits or tins).

    python scripts/fuzz_inputs.py [--kinds cxf,csv,colour,export,json,xlsx,xlsx-images,target,
        readings,readings-inspect,sprayout,record,recipe,poured,library,habits,habits-match,tolerance,
        cases,cases-cxf,manifest,model,model-register,lots,panel,database,database-shops,
        database-variants,cases-variants,car,deck,primers]
        [--n 200] [--seed 0] [--show]

It prints, per kind, how many damaged files were refused, read, and failed (with the file
kept under the work folder); ``--show`` prints one refusal of each kind of message. The exit
status is 1 when any failed.
"""

from __future__ import annotations

import argparse
import copy
import csv
import io
import json
import random
import re
import shutil
import sqlite3
import sys
import tempfile
import zipfile
from collections.abc import Callable
from dataclasses import replace
from datetime import datetime
from pathlib import Path

import numpy as np
import openpyxl
import torch
from typer.testing import CliRunner

from flakelab.cases.database import open_database
from flakelab.cases.exchange import read_cases, write_cases
from flakelab.cli.main import app
from flakelab.core.measurement import REFLECTANCE_RANGE, TEXTURE_RANGE
from flakelab.data import example_path
from flakelab.io import read_library, read_measurement, write_measurements, write_recipe
from flakelab.io.library_file import demo_library_path
from flakelab.io.lots_file import write_lots
from flakelab.library.lots import TonerLot, TonerLots
from flakelab.match.habits import ShopHabits, save_habits, write_habits
from flakelab.models.registry import shipped_model

HUGE_INTEGERS = ("1" + "0" * 21, "9" * 400)
"""Integers past 64 bits, and past a double's range, written out in digits (stop 128: each
was an internal error in the readers of habits, tins, spectra and libraries)."""
TOKENS = ("nan", "-1", "1e400", "1e300", "", "abc", "0", "Infinity", "1e-320", "[]", "{}", "null",
          "true", *HUGE_INTEGERS)  # fmt: skip
"""What a damaged number becomes."""
VALUES = (None, "x", -1, 0, 1e308, float("nan"), float("inf"), [], {}, True, [1, 2], {"a": 1},
          *map(int, HUGE_INTEGERS))  # fmt: skip
"""What a damaged JSON value becomes."""
CELLS = (None, "", "x", " 45as15 ", "45as15", "Name", "1,5", "=1/0", -1.0, 0, 1e308,
         float("nan"), float("inf"), True, datetime(2020, 1, 1))  # fmt: skip
"""What a damaged workbook cell becomes."""
SHEET_NAMES = ("Spectral Data", "Spectral data", "Color Data", "Texture Data", "Sheet")


def damage_text(text: str, rng: random.Random) -> str:
    lines = text.splitlines(keepends=True)
    kind = rng.randrange(10)
    if kind == 8:  # Excel's hint on the first line, naming the file's separator or another
        return f"sep={rng.choice([',', ';', chr(9), '|'])}\r\n" + text
    if kind == 9:  # the empty cells of a sheet once used further right, on some lines or all
        cut = rng.randrange(len(lines) + 1)
        return "".join([*lines[:cut], *(line.rstrip("\r\n") + ",,,\n" for line in lines[cut:])])
    if kind >= 6:  # a quote left open before a long run of cells, or nesting 100,000 deep
        i = rng.randrange(len(text))
        inserted = '"' + "0.5," * 40_000 if kind == 6 else "[" * 100_000 + "]" * 100_000
        return text[:i] + inserted + text[i:]
    if kind == 0 and lines:
        del lines[rng.randrange(len(lines))]
        return "".join(lines)
    if kind == 1 and lines:
        i = rng.randrange(len(lines))
        return "".join([*lines[: i + 1], *lines[i:]])
    if kind == 2 and (numbers := list(re.finditer(r"-?\d+\.?\d*(e-?\d+)?", text))):
        m = rng.choice(numbers)
        return text[: m.start()] + rng.choice(TOKENS) + text[m.end() :]
    if kind == 3:
        return text[: rng.randrange(len(text))]
    if kind == 4 and (names := list(re.finditer(r"[A-Za-z_]\w*", text))):
        m = rng.choice(names)
        return text[: m.end()] + "x" + text[m.end() :]
    i = rng.randrange(len(text))
    return text[:i] + rng.choice([",", '"', ";", "\t", "<", ">", "\x00", "é", "\n"]) + text[i:]


def damage_encoding(text: str, rng: random.Random) -> bytes:
    """``text`` as a spreadsheet or a cut copy may leave its bytes: a byte-order mark alone
    or before the text, the text in Windows-1252 with an 'é' in it, or cut inside one, or in
    UTF-16 (a spreadsheet's "Unicode Text"), perhaps cut inside a character, or UTF-16
    without its byte-order mark, as a script may write it."""
    kind = rng.randrange(6)
    if kind == 5:
        return text.encode(rng.choice(("utf-16-le", "utf-16-be")))
    if kind == 0:
        return b"\xef\xbb\xbf" + rng.choice((b"", b"\n"))
    if kind == 1:
        return b"\xef\xbb\xbf" + text.encode("utf-8")
    if kind == 4:
        data = text.encode("utf-16")
        return data if rng.random() < 0.5 else data[: rng.randrange(2, len(data))]
    i = rng.randrange(len(text))
    accented = text[:i] + "é" + text[i:]
    if kind == 2:
        return accented.encode("cp1252", errors="replace")
    data = accented.encode("utf-8")
    return data[: len(text[:i].encode("utf-8")) + 1]  # the é's first byte, and no more


def damage_json(document, rng: random.Random):
    """``document`` with one value anywhere replaced by a wrong one, or deleted."""
    document = copy.deepcopy(document)
    paths: list[list] = []

    def walk(node, path):
        paths.append(path)
        items = (
            node.items()
            if isinstance(node, dict)
            else enumerate(node)
            if isinstance(node, list)
            else ()
        )
        for key, value in items:
            walk(value, [*path, key])

    walk(document, [])
    if len(paths) == 1:
        return rng.choice(VALUES)
    *parents, last = rng.choice(paths[1:])
    parent = document
    for key in parents:
        parent = parent[key]
    if isinstance(parent, dict) and rng.random() < 0.25:
        del parent[last]
    else:
        parent[last] = copy.deepcopy(rng.choice(VALUES))
    return document


def odd_target(document, rng: random.Random):
    """A measurement document whose values stay readable but odd: one geometry's spectrum
    black, at the range's ends or random within it, or one texture reading at its range's
    ends, or the texture gone (what a match must meet without failing)."""
    document = copy.deepcopy(document)
    measurement = document["measurements"][0]
    kind = rng.randrange(4)
    if kind < 2:
        geometry = rng.choice(measurement["geometries"])
        low, high = REFLECTANCE_RANGE
        level = rng.choice((0.0, low, high, None))
        geometry["reflectance"] = [rng.uniform(0, high) if level is None else level
                                   for _ in geometry["reflectance"]]  # fmt: skip
    elif kind == 2:
        measurement["texture"][rng.choice(list(measurement["texture"]))] = rng.choice(TEXTURE_RANGE)
    else:
        measurement["texture"] = {}
    return document


def damage_workbook(data: bytes, rng: random.Random) -> bytes:
    """An MA-T12 export with one to three of: a cell replaced, a row or column deleted, a
    junk row inserted, a sheet removed, renamed or copied; or the file's bytes cut short; or
    one of its parts' XML damaged as text is (:func:`damage_part`)."""
    if rng.random() < 0.1:
        return data[: rng.randrange(len(data))]
    if rng.random() < 0.15:
        return damage_part(data, rng)
    workbook = openpyxl.load_workbook(io.BytesIO(data))
    for _ in range(rng.randint(1, 3)):
        sheet = rng.choice(workbook.worksheets)
        row, column = rng.randint(1, sheet.max_row), rng.randint(1, sheet.max_column)
        kind = rng.randrange(9)
        if kind < 4:
            sheet.cell(row, column).value = rng.choice(CELLS)
        elif kind == 4:
            sheet.delete_rows(row)
        elif kind == 5:
            sheet.delete_cols(column)
        elif kind == 6:
            sheet.insert_rows(row)
            sheet.cell(row, 1).value = rng.choice(CELLS)
        elif kind == 7 and len(workbook.worksheets) > 1:
            workbook.remove(sheet)
        else:
            title = rng.choice(SHEET_NAMES)
            if title not in workbook.sheetnames:
                sheet.title = title
            else:
                workbook.copy_worksheet(sheet)
    buffer = io.BytesIO()
    workbook.save(buffer)
    return buffer.getvalue()


def damage_part(data: bytes, rng: random.Random) -> bytes:
    """A workbook whose zip is whole but one XML part (a sheet, the shared strings, the
    workbook's own) damaged as :func:`damage_text` damages a text (stop 128: openpyxl's
    ParseError, LookupError, TypeError and IndexError were internal errors)."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(data)) as source, zipfile.ZipFile(buffer, "w") as target:
        parts = [n for n in source.namelist() if n.endswith((".xml", ".rels"))]
        broken = rng.choice(parts)
        for item in source.infolist():
            content = source.read(item)
            if item.filename == broken:
                content = damage_text(content.decode("utf-8"), rng).encode("utf-8")
            target.writestr(item, content)
    return buffer.getvalue()


CAMERA_ROWS = ("15as-45", "15as-30", "15as-15", "15as15", "15as45", "15as80", "15d")
"""An MA-T12 export's camera picture rows (sheet ``Texture Images``)."""


def add_camera_pictures(source: Path, path: Path, sample: str) -> None:
    """``source`` with a ``Texture Images`` sheet as the MA-T12 writes it: the sample's name
    heading column B, a small noise picture in each geometry's row."""
    from openpyxl.drawing.image import Image as Picture
    from PIL import Image

    workbook = openpyxl.load_workbook(source)
    sheet = workbook.create_sheet("Texture Images")
    sheet["B1"] = sample
    pixels = np.random.default_rng(0).integers(0, 256, (len(CAMERA_ROWS), 36, 48, 3))
    for row, (label, picture) in enumerate(zip(CAMERA_ROWS, pixels, strict=True), start=2):
        sheet.cell(row, 1).value = label
        png = io.BytesIO()
        Image.fromarray(picture.astype(np.uint8)).save(png, format="png")
        sheet.add_image(Picture(png), f"B{row}")
    workbook.save(path)


def damage_pictures(data: bytes, rng: random.Random) -> bytes:
    """An MA-T12 export with camera pictures, damaged as :func:`damage_workbook` does, or one
    of its pictures moved to another cell, or its bytes cut short or replaced."""
    if rng.random() < 0.5:
        return damage_workbook(data, rng)
    if rng.random() < 0.5:
        workbook = openpyxl.load_workbook(io.BytesIO(data))
        picture = rng.choice(workbook["Texture Images"]._images)
        picture.anchor._from.row = rng.randrange(12)
        picture.anchor._from.col = rng.randrange(4)
        buffer = io.BytesIO()
        workbook.save(buffer)
        return buffer.getvalue()
    buffer = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(data)) as source, zipfile.ZipFile(buffer, "w") as target:
        pictures = [n for n in source.namelist() if n.startswith("xl/media/")]
        broken = rng.choice(pictures)
        for item in source.infolist():
            content = source.read(item)
            if item.filename == broken:
                content = content[: rng.randrange(len(content))] if rng.random() < 0.5 else b"x"
            target.writestr(item, content)
    return buffer.getvalue()


CASE_COLUMNS = ("case_id", "shop", "instrument", "conditions", "outcome", "synthetic",
                "geometries", "recipe", "target", "sprayout", "target_texture",
                "sprayout_texture", "created_at", "updated_at", "tins", "colour_code",
                "target_recovered", "sprayout_recovered")  # fmt: skip
"""The columns of a case row that a damaged database changes."""
TABLE_COLUMNS = {
    "cases": CASE_COLUMNS,
    "models": ("name", "version", "instrument", "status", "toners", "data_hash", "metrics",
               "held_out_de00", "artefact", "created_at"),
    "shop_habits": ("shop", "model", "instrument", "report", "created_at"),
    "shop_lots": ("shop", "version", "document", "created_at"),
}  # fmt: skip
"""The columns of each table's rows that a damaged database changes (``database-shops``)."""
CELL_VALUES = (None, "", "x", "nonsense", 5, -1.0, 1e308, b"ab", b"", "[1, 2]", '{"a": 1}',
               '["45as15"]', '["zz"]', '{"Sa15": "x"}', "2026-13-45 25:00:00", "{",
               "null", '{"film_build": 1000000000000000000000}',
               "[1000000000000000000000]")  # fmt: skip
"""What a damaged database cell becomes."""


def damage_database(data: bytes, rng: random.Random, tables=("cases",)) -> bytes:
    """A SQLite database with one value of one row of one of ``tables`` replaced (a value its
    column's constraints refuse is drawn again)."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "shop.db"
        path.write_bytes(data)
        with sqlite3.connect(path) as connection:
            table = rng.choice(tables)
            rows = [r for (r,) in connection.execute(f"SELECT id FROM {table}")]
            while True:
                column, value = rng.choice(TABLE_COLUMNS[table]), rng.choice(CELL_VALUES)
                try:
                    connection.execute(f"UPDATE {table} SET {column} = ? WHERE id = ?",
                                       (value, rng.choice(rows)))  # fmt: skip
                    break
                except sqlite3.IntegrityError:
                    continue
        connection.close()
        return path.read_bytes()


def damage_model(data: bytes, rng: random.Random) -> bytes:
    stored = torch.load(io.BytesIO(data), weights_only=True)
    part = rng.choice(("meta", "norm", "state", "learned"))
    if part == "learned":  # the record of the cases it learned from
        learned = stored["learned"]
        stored["learned"] = rng.choice(
            (
                learned.flip(0),
                learned.float(),
                learned[:, None],
                torch.cat([learned, learned[:1]]),
                "c1,c2",
            )
        )
    elif part == "meta":
        stored["meta"] = json.dumps(damage_json(json.loads(stored["meta"]), rng))
    else:
        key = rng.choice(list(stored[part]))
        tensor = stored[part][key].clone()
        if rng.random() < 0.3:
            tensor = tensor[..., :-1]
        else:
            tensor.view(-1)[rng.randrange(tensor.numel())] = rng.choice(
                (float("nan"), float("inf"), 0.0, -1.0, 1e30)
            )
        stored[part][key] = tensor
    buffer = io.BytesIO()
    torch.save(stored, buffer)
    return buffer.getvalue()


def as_exported(source: Path, path: Path) -> None:
    """A CSV of L*a*b* alone (``source``) written as an instrument exports it: ``L*, a*, b*``
    with ``C*, h°`` beside, then ``X, Y, Z``, semicolons and decimal commas."""
    from flakelab.core.colorimetry import Conditions, Lab_to_LCh, Lab_to_XYZ, white_point

    rows = list(csv.reader(source.read_text().splitlines()))
    header, body = rows[0], rows[1:]
    at = header.index("L")
    lab = np.array([[float(v) for v in row[at : at + 3]] for row in body])
    conditions = Conditions.parse(body[0][header.index("lab_conditions")])
    extra = np.hstack(
        [Lab_to_LCh(lab)[:, 1:], 100 * Lab_to_XYZ(lab, white_point(conditions=conditions))]
    )
    header[at : at + 3] = ["L*", "a*", "b*", "C*", "h°", "X", "Y", "Z"]
    lines = [";".join(header)]
    for row, more in zip(body, extra, strict=True):
        cells = row[: at + 3] + [repr(float(v)) for v in more] + row[at + 3 :]
        lines.append(";".join(c.replace(".", ",") if _is_number(c) else c for c in cells))
    path.write_text("\n".join(lines) + "\n")


def as_panel_sheet(measurement, path: Path) -> None:
    """``measurement``'s colour at its 45° lamp's geometries as a spreadsheet of panels holds
    it: a row per sample, ``L* 15°`` columns (aspecular angles alone), semicolons, decimal
    commas."""
    at_45 = [i for i, g in enumerate(measurement.geometries) if g.illumination == 45]
    panel = replace(
        measurement,
        geometries=tuple(measurement.geometries[i] for i in at_45),
        reflectance=measurement.reflectance[at_45],
        stored_lab=measurement.lab()[at_45],
        spectra_recovered=True,
    )
    write_measurements([panel], path, wide=True, decimal_comma=True)
    text = path.read_text(encoding="utf-8-sig")
    header, rest = text.split("\n", 1)
    path.write_text(re.sub(r" 45as(-?\d+)", r" \1°", header) + "\n" + rest, encoding="utf-8")


def sheet_saved_as_csv(export: Path, sheet: str, path: Path) -> None:
    """One sheet of an MA-T12 export saved as CSV, as a spreadsheet saves the sheet it shows."""
    import openpyxl

    workbook = openpyxl.load_workbook(export, read_only=True)
    with path.open("w", newline="", encoding="utf-8") as out:
        csv.writer(out).writerows(
            ["" if c is None else c.strftime("%d.%m.%Y %H:%M") if hasattr(c, "strftime") else c
             for c in row]
            for row in workbook[sheet].iter_rows(values_only=True)
        )  # fmt: skip
    workbook.close()


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def good_files(work: Path) -> dict[str, tuple[Path, Callable[[Path], list[str]]]]:
    """Each kind's good file and the command that reads a file of its kind."""
    target, sprayout = example_path("target"), example_path("sprayout")
    recipe = target.parent / "blue-metallic-recipe.json"
    measurement = read_measurement(target)
    write_measurements([measurement], work / "good.csv")
    colour = replace(measurement, stored_lab=measurement.lab(), spectra_recovered=True)
    write_measurements([colour], work / "colour.csv")  # L*a*b* alone: spectra recovered
    as_exported(work / "colour.csv", work / "export.csv")
    both = [measurement, read_measurement(sprayout)]
    write_measurements(both, work / "wide.csv", wide=True)  # a row per sample
    as_panel_sheet(measurement, work / "panels.csv")
    write_measurements([measurement], work / "good.json")
    write_measurements([read_measurement(sprayout)], work / "sprayout.json")
    write_measurements([measurement], work / "good.xlsx")
    add_camera_pictures(work / "good.xlsx", work / "pictures.xlsx", measurement.sample)
    sheet_saved_as_csv(work / "good.xlsx", "Spectral Data", work / "sheet.csv")
    spots = [replace(measurement, sample=f"spot {i}", stored_lab=None) for i in (1, 2, 3)]
    write_measurements(spots, work / "spots.json")
    habits = ShopHabits(np.array([0.04, np.log(0.96), 0.005]), np.array([0.02, 0.001, 0.001]), 200,
                        "demo-five-angle", "shop A")  # fmt: skip
    write_habits(habits, work / "habits.json")
    tolerance = {"name": "shop", "kL": 1.0, "default": {"de00": 1.2},
                 "geometries": {"45as15": {"dL": 2.0, "dC": 1.0, "dH": 0.8}},
                 "texture": {"G": 1.0, "SG": 0.5}}  # fmt: skip
    (work / "tolerance.json").write_text(json.dumps(tolerance))
    write_recipe(json.loads(recipe.read_text()), work / "recipe.json")
    for suffix in ("csv", "cxf"):
        cases = work / f"cases.{suffix}"
        CliRunner().invoke(app, ["cases", "generate", "--n", "4", "--seed", "3", "--out", cases])
        write_cases([replace(c, colour_code="Toyota 1G3") for c in read_cases(cases)], cases)
    CliRunner().invoke(app, ["cases", "import", f"{work}/cases.csv", "-d", f"{work}/shop.db"])
    CliRunner().invoke(app, ["cases", "variants", "1G3", "-d", f"{work}/shop.db", "--within",
                             "0.1", "--out", f"{work}/deck.json"])  # fmt: skip
    for suffix in ("csv", "cxf"):  # readings known by their L*a*b* alone, as shops record them
        cases = work / f"cases.{suffix}"
        write_cases([replace(c, target_recovered=i == 1, sprayout_recovered=i == 2)
                     for i, c in enumerate(read_cases(cases))], cases)  # fmt: skip
    model = replace(shipped_model("five-angle"))  # a copy recording cases, as a shop's does
    model.add_learned([f"case {i}" for i in range(50)])
    (work / "model.pt").write_bytes(model.to_bytes())
    for name, path in (("car.cxf", target), ("spray.cxf", sprayout), ("shot.json", recipe)):
        shutil.copy(path, work / name)
    (work / "manifest.csv").write_text(
        "target,recipe,sprayed,shop,outcome,at,case_id,colour_code\n"
        "car.cxf,shot.json,spray.cxf,shop A,auto,2026-01-02T10:00:00,c1,NH-731P\n"
        "car.cxf,shot.json,spray.cxf,shop A,corrected,2026-01-03 11:30:00,c2,\n"
    )
    shutil.copy(demo_library_path(), work / "library.json")
    read_library(work / "library.json")
    tins = [TonerLot("Phthalo blue GS", 1.03, 0.01, "B-1", 1, "2026-11-30T08:00:00+00:00", "m",
                     0.6, 0.4),
            TonerLot("Al medium", 0.98)]  # fmt: skip
    read_with = {(("Al medium", "strength"), ("Phthalo blue GS", "strength")): 0.9}
    write_lots(TonerLots(TonerLots.of(tins).lots, "flakelab demo", read_with), work / "lots.json")
    panel = target.parent / "phthalo-blue-panel.cxf"
    write_measurements([read_measurement(panel)], work / "panel.json")
    panel_recipe, standard = (
        target.parent / f"phthalo-blue-panel{s}" for s in ("-recipe.json", "-standard.cxf")
    )
    write_primers(work / "primers.csv")
    shops = work / "shops.db"  # a row of each table: cases, a shop's model, habits and tins
    shutil.copy(work / "shop.db", shops)
    with torch.no_grad():  # the shop's own: weights of its own, as an adaptation gives
        for weights in model.network.parameters():
            weights.add_(1e-4)
    (work / "shop-model.pt").write_bytes(model.to_bytes())
    for command in (["model", "register", str(work / "shop-model.pt"), str(work / "cases.csv")],
                    ["lots", "save", str(work / "lots.json")]):  # fmt: skip
        made = CliRunner().invoke(app, [*command, "--shop", "synthetic shop", "-d", str(shops)])
        assert made.exit_code == 0, made.output
    save_habits(open_database(shops), replace(habits, shop="synthetic shop"), "five-angle")
    return {
        "cxf": (target, lambda p: ["inspect", str(p)]),
        "csv": (work / "good.csv", lambda p: ["inspect", str(p)]),
        # a car read as L*a*b* alone, its spectra recovered, matched by the main job
        "colour": (work / "colour.csv", lambda p: ["match", str(p), "--candidates", "1"]),
        "export": (work / "export.csv", lambda p: ["inspect", str(p)]),
        # a row per sample: spectra at each geometry; colour headed by aspecular angles alone
        "wide": (work / "wide.csv", lambda p: ["compare", str(p), str(target)]),
        "panels": (work / "panels.csv", lambda p: ["match", str(p), "--candidates", "1"]),
        # an MA-T12 export's Spectral Data sheet saved as CSV
        "sheet": (work / "sheet.csv", lambda p: ["inspect", str(p)]),
        "json": (work / "good.json", lambda p: ["inspect", str(p)]),
        "xlsx": (work / "good.xlsx", lambda p: ["inspect", str(p)]),
        # an export with the camera's pictures, drawn by inspect --images
        "xlsx-images": (work / "pictures.xlsx",
                        lambda p: ["inspect", str(p), "--images", str(work / "pictures.png")]),
        # a damaged target read by the main job, whose search and tables meet every value
        "target": (work / "good.json", lambda p: ["match", str(p), "--candidates", "1"]),
        # the car read at three spots, the readings averaged by the main job
        "readings": (work / "spots.json",
                     lambda p: ["match", str(p), "--average", "--candidates", "1"]),
        "readings-inspect": (work / "spots.json", lambda p: ["inspect", str(p), "--average"]),
        # a damaged spray-out read by the correction, which meets it with the recipe's model
        "sprayout": (work / "sprayout.json",
                     lambda p: ["correct", str(target), "--recipe", str(recipe), "--sprayed",
                                str(p), "--extra-toners", "0"]),
        # the same recorded as a shop's case, and checked against its recipe's prediction
        "record": (work / "sprayout.json",
                   lambda p: ["cases", "record", str(target), "--recipe", str(recipe),
                              "--sprayed", str(p), "-d", "sqlite://"]),
        "recipe": (work / "recipe.json", lambda p: ["weigh", str(p)]),
        # the same weighed after black ran over, or went in by mistake, into a bounded can
        "poured": (work / "recipe.json",
                   lambda p: ["weigh", str(p), "--poured", "Carbon black=5", "--most", "300g"]),
        # a can by volume, so that the toners' densities are used as well as read
        "library": (work / "library.json",
                    lambda p: ["weigh", str(recipe), "--library", str(p), "--physics",
                               "--quantity", "1qt"]),
        "habits": (work / "habits.json",
                   lambda p: ["correct", str(target), "--recipe", str(recipe), "--sprayed",
                              str(sprayout), "--habits", str(p), "--extra-toners", "0"]),
        # the same file read by the match, which aims its candidates off for the habits
        "habits-match": (work / "habits.json",
                         lambda p: ["match", "--example", "--candidates", "1", "--habits",
                                    str(p)]),
        "tolerance": (work / "tolerance.json",
                      lambda p: ["compare", str(target), str(sprayout), "-t", str(p)]),
        "cases": (work / "cases.csv", lambda p: ["cases", "import", str(p), "-d", "sqlite://"]),
        "cases-cxf": (work / "cases.cxf",
                      lambda p: ["cases", "import", str(p), "-d", "sqlite://"]),
        "manifest": (work / "manifest.csv",
                     lambda p: ["cases", "record-all", str(p), "-d", "sqlite://"]),
        "model": (work / "model.pt", lambda p: ["weigh", str(recipe), "--model", str(p)]),
        # the same registered against generated cases, judged against the current model
        "model-register": (work / "model.pt",
                           lambda p: ["model", "register", str(p), str(work / "cases.csv"),
                                      "-d", "sqlite://"]),
        # a shop's database with one value of one case row replaced, as another tool or a
        # hand might write it (SQLite keeps whatever it is given), read whole by an export
        "database": (work / "shop.db",
                     lambda p: ["cases", "export", str(work / "export.csv"), "-d", str(p)]),
        # the same for any row of a database holding a shop's cases, model, habits and tins,
        # every one read by the shops' summary
        "database-shops": (shops, lambda p: ["cases", "shops", "-d", str(p)]),
        # the same, and a case file, read by a colour code's variants (the case file's
        # written as a chip book); a damaged car in the booth held against them
        "database-variants": (work / "shop.db",
                              lambda p: ["cases", "variants", "1G3", "-d", str(p)]),
        "cases-variants": (work / "cases.csv",
                           lambda p: ["cases", "variants", "1G3", "-d", str(p), "--out",
                                      str(work / "chips.cxf")]),
        # a deck of standards (the shop's variant chips) a car is ranked against
        "deck": (work / "deck.json",
                 lambda p: ["compare", str(p), str(work / "good.json"), "--nearest", "3"]),
        "car": (work / "good.json",
                lambda p: ["cases", "variants", "1G3", "-d", str(work / "shop.db"), "--car",
                           str(p)]),
        # the shop's tins, which the main job weighs for
        "lots": (work / "lots.json",
                 lambda p: ["match", "--example", "--candidates", "1", "--lots", str(p)]),
        # a shop's primers, which hiding chooses among
        "primers": (work / "primers.csv",
                    lambda p: ["hiding", str(recipe), "--primers", str(p)]),
        # a calibration panel's spray-out, its tins read against the standard's panel
        "panel": (work / "panel.json",
                  lambda p: ["lots", "calibrate", str(p), "--recipe", str(panel_recipe),
                             "--standard", str(standard), "--lots", str(work / "lots.json"),
                             "--dry-run"]),
    }  # fmt: skip


def write_primers(path: Path) -> None:
    """Four of the ColorChecker's patches (Ohta's measured spectra) as a shop's primers, read
    alike at the five-angle geometries, as a matte panel is."""
    import colour

    from flakelab.core.geometry import instrument_geometries
    from flakelab.core.measurement import Measurement
    from flakelab.core.spectra import WAVELENGTHS

    patches = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]
    geometries = instrument_geometries("five-angle")
    write_measurements([
        Measurement(sample=name, geometries=geometries, wavelengths=WAVELENGTHS,
                    reflectance=np.tile(patches[name].copy().align(colour.SpectralShape(
                        400, 700, 10)).values, (len(geometries), 1)))
        for name in ("neutral 8 (.23 D)", "neutral 5 (.70 D)", "red", "yellow")
    ], path)  # fmt: skip


def failure(result) -> str | None:
    """What is wrong with how the CLI met a damaged file, or None."""
    said = result.stdout + result.stderr
    if result.exit_code == 70 or "internal error" in said:
        return result.stderr.strip()[-300:]
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        return repr(result.exception)[:300]
    if "Traceback" in said or "Warning" in said:
        return said[-300:]
    if result.exit_code == 0 and re.search(r"\b(nan|inf|infinity)\b", result.stdout, re.I):
        return "NaN or infinity in the output"
    if result.exit_code not in (0, 2):
        return f"exit status {result.exit_code}"
    return None


def fuzz(kind: str, good: Path, command, n: int, rng: random.Random, work: Path) -> dict:
    runner, counts, messages, failed = CliRunner(), {"refused": 0, "read": 0}, {}, []
    data = good.read_bytes()
    for i in range(n):
        damaged = work / f"{kind}-{i}{good.suffix}"
        if kind.startswith("model"):
            damaged.write_bytes(damage_model(data, rng))
        elif kind in ("database", "database-variants"):
            damaged.write_bytes(damage_database(data, rng))
        elif kind == "database-shops":
            damaged.write_bytes(damage_database(data, rng, tuple(TABLE_COLUMNS)))
        elif kind == "xlsx":
            damaged.write_bytes(damage_workbook(data, rng))
        elif kind == "xlsx-images":
            damaged.write_bytes(damage_pictures(data, rng))
        elif kind in ("target", "sprayout", "record", "car") and rng.random() < 0.5:
            damaged.write_text(json.dumps(odd_target(json.loads(data), rng)))
        elif good.suffix == ".json" and rng.random() < 0.7:
            damaged.write_text(json.dumps(damage_json(json.loads(data), rng)))
        elif rng.random() < 0.15:
            damaged.write_bytes(damage_encoding(data.decode("utf-8"), rng))
        else:
            damaged.write_text(damage_text(data.decode("utf-8"), rng), encoding="utf-8")
        result = runner.invoke(app, command(damaged))
        if problem := failure(result):
            failed.append((damaged, problem))
            continue
        damaged.unlink()
        if result.exit_code == 0:
            counts["read"] += 1
            continue
        counts["refused"] += 1
        line = result.stderr.strip().splitlines()[-1]
        messages.setdefault(re.sub(r"\d+", "N", line.replace(str(damaged), "FILE"))[:120], line)
    return {**counts, "failed": failed, "messages": messages}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--kinds", help="comma-separated (default: every kind)")
    parser.add_argument("--n", type=int, default=200, help="damaged files of each kind")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--show", action="store_true", help="one refusal of each kind of message")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="flakelab-fuzz-"))
    kinds = good_files(work)
    rng = random.Random(args.seed)
    failures = 0
    for kind in args.kinds.split(",") if args.kinds else kinds:
        if kind not in kinds:
            parser.error(f"--kinds: {kind!r} is not one of {', '.join(kinds)}")
        report = fuzz(kind, *kinds[kind], args.n, rng, work)
        failures += len(report["failed"])
        print(f"{kind:>16}: {report['refused']} refused, {report['read']} read, "
              f"{len(report['failed'])} failed", flush=True)  # fmt: skip
        for path, problem in report["failed"]:
            print(f"           FAILED {path}: {problem}")
        if args.show:
            for line in report["messages"].values():
                print(f"           {line[:150]}")
    print(f"damaged files left in {work}" if failures else "", end="\n" if failures else "")
    if not failures:
        shutil.rmtree(work)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
