"""Learned forward model: storage, training protocol, outliers, registry, shipped models."""

from __future__ import annotations

import io
import json
import re
from dataclasses import replace

import numpy as np
import pytest
import torch

from flakelab.cases.database import open_database
from flakelab.cases.generator import World
from flakelab.core.measurement import TEXTURE_READINGS
from flakelab.errors import Note
from flakelab.io import read_library
from flakelab.library import Library
from flakelab.models.files import model_file_description
from flakelab.models.network import ForwardModel, ModelError
from flakelab.models.registry import (
    SHIPPED,
    list_models,
    load_model_file,
    promote,
    promoted_model,
    register,
    retire,
    shipped_model,
    shipped_model_path,
)
from flakelab.models.training import (
    SCREENINGS,
    CaseArrays,
    TrainingConfig,
    _new_model,
    adapt_model,
    effect_share_floor,
    evaluate_model,
    fit,
    flag_outliers,
    generated_case_arrays,
    protocol_epochs,
    protocol_stages,
    recorded_config,
    too_few_readings,
    train_protocol,
    training_device,
)

LIBRARY = read_library(None)
EFFECT = [t.kind != "pigment" for t in LIBRARY.toners]
# a small shop (2 aluminium, 1 pearl, 4 pigments): 400 cases teach a model enough to judge
SMALL = Library(
    "small shop",
    tuple(
        LIBRARY[n]
        for n in (
            "Al medium",
            "Al coarse",
            "Pearl silver white",
            "Phthalo blue GS",
            "Quinacridone red",
            "Iron oxide yellow",
            "Carbon black",
        )
    ),
    LIBRARY.binder,
)
QUICK = TrainingConfig(hidden=(64, 64), epochs=100, finetune_epochs=30, batch_size=16, seed=1)


@pytest.fixture(scope="module")
def data() -> CaseArrays:
    return generated_case_arrays(World(SMALL, "five-angle"), 400, seed=21)


@pytest.fixture(scope="module")
def trained(data):
    return train_protocol(data, QUICK)


def with_meta(model: ForwardModel, **changes) -> bytes:
    """``model``'s file with entries of its metadata changed."""

    def edit(stored):
        stored["meta"] = json.dumps(json.loads(stored["meta"]) | changes)

    return _with_stored(model, edit)


def corrupted(data: CaseArrays, rows: list[int]) -> CaseArrays:
    R = data.R.copy()
    R[rows] = R[rows][:, :, ::-1] * 2.5  # a gross error: wrong panel, reversed spectrum
    return replace(data, R=R)


def test_model_survives_a_round_trip_through_bytes(trained, data):
    model, _ = trained
    again = ForwardModel.from_bytes(model.to_bytes())
    a, ta = model.predict(data.x[:20])
    b, tb = again.predict(data.x[:20])
    np.testing.assert_allclose(a, b, rtol=1e-6)
    np.testing.assert_allclose(ta, tb, rtol=1e-6, atol=1e-6)


def test_a_model_records_the_cases_it_learned_from(trained, data):
    """The protocol's model learned the cleaned cases, not the outliers it dropped; adapted,
    it has learned the adaptation's cases too, not those that chose its epoch. The record
    survives storage; a malformed one is refused; the shipped models have none."""
    model, report = trained
    outliers = set(report["outlier_case_ids"])
    assert model.learned_from(data.case_ids).tolist() == [c not in outliers for c in data.case_ids]
    fresh = generated_case_arrays(World(SMALL, "five-angle"), 100, seed=77)
    assert not model.learned_from(fresh.case_ids).any()
    config = replace(QUICK, adapt_epochs=2, adapt_validation=0.2)
    adapted, adaptation = adapt_model(model, fresh, config)
    assert adapted.learned_from(fresh.case_ids).sum() == adaptation["cases"] == 80
    assert adapted.learned_from(data.case_ids).sum() == len(data.case_ids) - len(outliers)
    assert not model.learned_from(fresh.case_ids).any()  # the model it came from unchanged
    again = ForwardModel.from_bytes(adapted.to_bytes())
    np.testing.assert_array_equal(again.learned, adapted.learned)
    for bad, problem in ((torch.tensor([3, 1]), "sorted"), (torch.tensor([1.5]), "64-bit")):
        edited = _with_stored(model, lambda stored, bad=bad: stored.update(learned=bad))
        with pytest.raises(ModelError, match=f"m.pt: learned: expected .*{problem}"):
            ForwardModel.from_bytes(edited, source="m.pt")
    assert shipped_model("five-angle").learned is None


def test_a_new_version_is_judged_on_cases_neither_model_learned(trained, data, database_url):
    """Retrained on a grown database, a model is held-out judged against the current one on
    cases the current one may have learned: those are left out, or it would be flattered."""
    engine = open_database(database_url)
    current, report = trained
    fresh = generated_case_arrays(World(SMALL, "five-angle"), 60, seed=78)
    first = register(engine, current, fresh)
    promote(engine, first["name"], first["version"])
    retrained = replace(ForwardModel.from_bytes(current.to_bytes()), learned=None)
    judged = register(engine, retrained, data.joined(fresh))
    # the current model learned data's cases but for the outliers it dropped
    assert judged["cases_judged"] == len(fresh.case_ids) + report["outliers"]
    # the same weights, judged on the same cases: no better, not promoted
    assert judged["held_out_de00"] == pytest.approx(judged["incumbent_de00"])
    assert not judged["promoted"]


def test_log_features_widen_the_input_and_survive_storage(data):
    config = replace(QUICK, epochs=2, finetune_epochs=1, log_offset=0.01)
    model = _new_model(data, config, np.arange(50))
    T = len(data.toners)
    x = torch.as_tensor(data.x[:5])
    features = model.features(x)
    assert features.shape == (5, 3 * T)
    np.testing.assert_allclose(features[:, 2 * T :], np.log(data.x[:5] + 0.01), rtol=1e-12)
    again = ForwardModel.from_bytes(model.to_bytes())
    assert again.log_offset == 0.01
    np.testing.assert_allclose(again.predict(data.x[:5])[0], model.predict(data.x[:5])[0])
    plain = _new_model(data, replace(config, log_offset=0.0), np.arange(50))
    assert plain.features(x).shape == (5, 2 * T)
    # a file whose log_offset is wrong, or disagrees with its weights, is refused
    for offset, problem in (("0.01", "log_offset: expected"), (0.0, "weights do not fit")):
        with pytest.raises(ModelError, match=f"m.pt: {problem}"):
            ForwardModel.from_bytes(with_meta(model, log_offset=offset), source="m.pt")


def _with_stored(model: ForwardModel, edit) -> bytes:
    """``model``'s file after ``edit`` of its stored dictionary (meta, state, norm)."""
    stored = torch.load(io.BytesIO(model.to_bytes()), weights_only=True)
    edit(stored)
    return _saved(stored)


def _set_info(**changes):
    def edit(stored):
        meta = json.loads(stored["meta"])
        meta["info"] |= changes
        stored["meta"] = json.dumps(meta)

    return edit


def _set_tensor(part: str, key: str, value: float, cut: bool = False):
    def edit(stored):
        tensor = stored[part][key].clone()
        tensor.view(-1)[3] = value
        stored[part][key] = tensor[:-1] if cut else tensor

    return edit


@pytest.mark.parametrize(
    ("edit", "problem"),
    [  # each was an internal error (a shape or type met in arithmetic), or predicted NaN
        (_set_info(toner_cases={"Al medium": "many"}), "info.toner_cases: expected the model's"),
        (_set_info(novel_toners=["Unobtainium"]), "info.novel_toners: expected a list of"),
        (_set_info(effect_share_floor="x"), "info.effect_share_floor: expected a share"),
        (_set_tensor("norm", "x_mean", 0.0, cut=True), "norm x_mean: expected 70 numbers, got"),
        (_set_tensor("norm", "y_std", 0.0), "norm y_std: expected positive finite numbers"),
        (_set_tensor("norm", "y_mean", np.nan), "norm y_mean: expected finite numbers"),
        (_set_tensor("state", "weights.0", np.nan), "weights: expected finite numbers"),
    ],
)
def test_a_damaged_model_file_is_named_by_its_field(edit, problem):
    shipped = shipped_model("five-angle")
    with pytest.raises(ModelError, match=f"^m.pt: {re.escape(problem)}"):
        ForwardModel.from_bytes(_with_stored(shipped, edit), source="m.pt")


@pytest.mark.parametrize(
    ("changes", "problem"),
    [
        ({"toners": ["A", "A"]}, "toners: expected a list of distinct toner names"),
        ({"geometries": ["45as15", "45xx25"]}, "geometries: expected a geometry name"),
        ({"hidden": [100, 10**9]}, "hidden: expected a list of layer widths from 1 to 4096"),
        ({"members": 10**6}, "members: expected a whole number from 1 to 64"),
        ({"texture": ["G"]}, "texture: expected the readings"),
        ({"effect": [1]}, "effect: expected 35 flags of 0 or 1, one a toner"),
    ],
)
def test_a_model_file_s_description_is_checked_before_its_network_is_built(changes, problem):
    shipped = shipped_model("five-angle")
    with pytest.raises(ModelError, match=f"^m.pt: {re.escape(problem)}"):
        ForwardModel.from_bytes(with_meta(shipped, **changes), source="m.pt")


@pytest.mark.parametrize("instrument", list(SHIPPED))
def test_a_model_file_s_description_reads_as_loading_it_does(instrument):
    """`model list` reads the shipped models' toners and data without torch: the description
    must be the one the whole file gives, weights and all."""
    path = shipped_model_path(instrument)
    described, model = model_file_description(path), shipped_model(instrument)
    assert tuple(described["toners"]) == model.toners
    assert tuple(described["geometries"]) == model.geometries
    assert (described["instrument"], described["info"]) == (model.instrument, model.info)


def test_a_file_that_is_no_model_has_no_description(tmp_path):
    shipped = shipped_model("five-angle")
    files = {
        "text.pt": b"not a model",
        "cut.pt": shipped.to_bytes()[:5000],
        "other.pt": with_meta(shipped, format="something-else"),
        "toners.pt": with_meta(shipped, toners="A, B"),
        "tensor.pt": _saved(torch.zeros(3)),
    }
    problems = (
        "(BadZipFile)",
        "(BadZipFile)",
        "format: expected 'flakelab-model'",
        "toners: expected a list",
        "(TypeError)",
    )
    for (name, content), problem in zip(files.items(), problems, strict=True):
        (tmp_path / name).write_bytes(content)
        with pytest.raises(ModelError, match=f"{name}: .*{re.escape(problem)}"):
            model_file_description(tmp_path / name)
    for path, problem in ((tmp_path / "none.pt", "no such model file"), (tmp_path, "a folder")):
        with pytest.raises(ModelError, match=problem):
            model_file_description(path)


def test_both_readers_of_a_model_file_refuse_one_that_is_not_alike(tmp_path):
    """The whole model (torch) and its description (without) check the format in one place
    (flakelab.models.files): a file of another format or with no description is refused by
    both in the same words."""
    files = {
        "other.pt": with_meta(shipped_model("five-angle"), format="something-else"),
        "meta.pt": _saved({"meta": "{not JSON", "state": {}}),
    }
    problems = ("format: expected 'flakelab-model'", "not a flakelab model file (JSONDecodeError)")
    for (name, content), problem in zip(files.items(), problems, strict=True):
        path = tmp_path / name
        path.write_bytes(content)
        with pytest.raises(ModelError) as described:
            model_file_description(path)
        with pytest.raises(ModelError) as loaded:
            load_model_file(path)
        assert str(described.value) == str(loaded.value) == f"{path}: {problem}"


def _saved(stored) -> bytes:
    buffer = io.BytesIO()
    torch.save(stored, buffer)
    return buffer.getvalue()


def test_training_learns_far_better_than_the_mean(trained, data):
    model, report = trained
    assert report["log"][-1]["loss"] < 0.5 * report["log"][0]["loss"]
    mean_model = evaluate_model(model, data)
    R_mean = np.exp(np.log(np.maximum(data.R, 1e-3)).mean(0))
    from flakelab.core.colorimetry import reflectance_to_Lab
    from flakelab.core.difference import delta_E

    baseline = delta_E(reflectance_to_Lab(data.R), reflectance_to_Lab(R_mean[None])).mean()
    assert mean_model["de00_mean"] < 0.5 * baseline


def test_the_figures_per_paint_family_make_up_the_whole(trained, data):
    model, _ = trained
    families = SMALL.paint_families(data.x)
    report = evaluate_model(model, data, families=families)
    per_family = report["per_family"]
    assert set(per_family) == {"metallic", "pearl", "solid"}
    assert sum(f["cases"] for f in per_family.values()) == report["cases"]
    weighted = sum(f["cases"] * f["de00_mean"] for f in per_family.values()) / report["cases"]
    assert weighted == pytest.approx(report["de00_mean"], rel=1e-9)
    assert max(f["de00_max"] for f in per_family.values()) == report["de00_max"]
    # each family's figures are those of its cases alone
    alone = evaluate_model(model, data.subset(np.flatnonzero(families == "pearl")))
    assert per_family["pearl"]["de00_p95"] == pytest.approx(alone["de00_p95"], rel=1e-6)


def test_too_few_cases_for_the_network_s_weights_are_said_to_be_so():
    """A network learns a case's readings (reflectance at each geometry and wavelength, and
    texture) with its weights: fewer readings than weights and it can fit every case and
    learn little else, which 'train' said nothing of (25 cases, 4,075 readings, 43,763
    weights). The shipped five-angle model's 119,820 cases give 446 readings a weight of each
    of its four networks."""
    model = shipped_model()
    assert (len(model.x_mean), model.hidden, len(model.y_mean)) == (70, (100, 100, 100), 163)
    weights = 71 * 100 + 2 * 101 * 100 + 101 * 163  # 43,763, counted by hand
    # an ensemble of four networks, each learning every case with as many weights
    assert model.members * weights == sum(p.numel() for p in model.network.parameters())
    note = too_few_readings(model, 25)
    assert "25 cases give 4,075 readings to learn, fewer than the network's 43,763" in note
    assert too_few_readings(model, -(-weights // 163)) is None  # as many readings as weights
    assert too_few_readings(model, -(-weights // 163) - 1) is not None
    assert too_few_readings(model, model.info["trained_cases"]) is None
    few = generated_case_arrays(World(SMALL, "five-angle"), 25, seed=3)
    with pytest.warns(Note, match="25 cases give 4,075 readings to learn"):
        train_protocol(few, replace(QUICK, epochs=1, finetune_epochs=1))


@pytest.mark.parametrize(
    "screening",  # the paper's sequential screen in the suite, the other a validation run
    [pytest.param(s, marks=[pytest.mark.slow] * (s != "sequential")) for s in SCREENINGS],
)
def test_gross_errors_are_flagged_and_dropped(data, screening):
    """Five cases read off a wrong panel (each 15 ΔE00 or more from its own) are flagged
    among the 400. Until stop 115 the test's rows were 3, 50, 120, 200 and 399; row 50, a
    dark grey metallic (reflectance ≤ 0.05), reads 12.6 from its own when reversed, and the
    quick model of stop 115's world errs more on the cases themselves (median 2.3, cut 10.6,
    its worst own cases 14–16), so the sequential screen judged row 50 at 10.2, under its
    cut. Row 52 (16.5 from its own) stands in for it."""
    from flakelab.core.colorimetry import reflectance_to_Lab
    from flakelab.core.difference import delta_E

    bad_rows = [3, 52, 120, 200, 399]
    gross = delta_E(reflectance_to_Lab(corrupted(data, bad_rows).R), reflectance_to_Lab(data.R))
    assert gross[bad_rows].mean(axis=1).min() > 15
    config = replace(QUICK, screening=screening)
    _, report = train_protocol(corrupted(data, bad_rows), config)
    flagged = set(report["outlier_case_ids"])
    assert {data.case_ids[i] for i in bad_rows} <= flagged
    assert len(flagged) <= len(bad_rows) + 6


def test_sequential_screen_trains_one_model_a_session_per_partition(trained):
    """The paper's first stage: four sessions, one partition each, then the final model; the
    progress total counts every logged epoch."""
    _, report = trained
    stages = list(dict.fromkeys(entry["stage"] for entry in report["log"]))
    sessions = [f"partition {k}" for k in range(1, QUICK.folds)]
    assert stages == [s for k in sessions for s in (k, f"{k} fine-tune")] + [
        "final",
        "final fine-tune",
    ]
    assert len(report["log"]) == protocol_epochs(QUICK)


def test_a_training_s_losses_lie_on_one_time_axis(data, tmp_path):
    """What ``train --plot`` draws: stages trained one after another follow each other, epoch
    by epoch; members trained side by side (their entries interleaved) share their epochs."""
    from flakelab.render.plots import _epoch_steps, plot_losses

    config = replace(QUICK, hidden=(4,), epochs=3, finetune_epochs=2, members=2)
    _, report = train_protocol(data, config)
    log = report["log"]
    steps = _epoch_steps(log)
    at = {}
    for entry, step in zip(log, steps, strict=True):
        at.setdefault(entry["stage"], []).append(step)
    for stage, places in at.items():  # one step an epoch, in order
        assert places == list(range(places[0], places[0] + len(places))), stage
    order = [f"partition {k}{f}" for k in range(1, config.folds) for f in ("", " fine-tune")]
    for before, after in zip(order, order[1:] + ["final 1"], strict=True):
        assert at[after][0] == at[before][-1] + 1, (before, after)
    assert at["final 1"] == at["final 2"] and at["final 1 fine-tune"] == at["final 2 fine-tune"]
    assert max(steps) == 4 * (3 + 2) + (3 + 2) - 1
    plot_losses(log, tmp_path / "losses.svg")
    assert (tmp_path / "losses.svg").read_text().count("<!-- partition ") == 8


def _weights(model: ForwardModel) -> list[np.ndarray]:
    return [v.numpy() for _, v in sorted(model.network.state_dict().items())]


@pytest.mark.parametrize(
    ("screening", "cut", "kept"),
    [  # stages of 4 and 3 epochs, a progress step per network an epoch
        ("sequential", 13, 3),  # within partition 2's fine-tuning
        ("sequential", 33, 8),  # within the final training: the outliers kept, not the screen
        ("cross-validation", 30, 1),  # within the folds' fine-tuning: five networks kept
    ],
)
def test_an_interrupted_protocol_goes_on_from_its_checkpoint_to_the_same_model(
    data, tmp_path, screening, cut, kept
):
    """A training stopped after ``cut`` epochs and run again from its checkpoint ends with
    the uninterrupted one's networks, log and outliers, bit for bit: each stage's batches
    are seeded by the log's length and each starts a new optimiser."""
    from flakelab.models.checkpoint import TrainingCheckpoint
    from flakelab.models.training import data_hash

    data = data.subset(np.arange(160))
    config = replace(
        QUICK, hidden=(8,), epochs=4, finetune_epochs=3, members=2, screening=screening
    )
    whole, whole_report = train_protocol(data, config)
    path = tmp_path / "run.ckpt"
    seen = []

    def stop_at_cut(epochs: int) -> None:
        seen.append(epochs)
        if sum(seen) >= cut:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train_protocol(data, config, progress=stop_at_cut, checkpoint=TrainingCheckpoint(
            path, config, data_hash(data)))  # fmt: skip
    checkpoint = TrainingCheckpoint(path, config, data_hash(data))
    assert checkpoint.stages == kept and path.exists() == (kept > 0)
    again, report = train_protocol(data, config, checkpoint=checkpoint)
    for ours, theirs in zip(_weights(again), _weights(whole), strict=True):
        np.testing.assert_array_equal(ours, theirs)
    assert report["log"] == whole_report["log"]
    assert report["outlier_case_ids"] == whole_report["outlier_case_ids"]


def test_a_checkpoint_of_another_training_or_a_damaged_one_is_refused(data, tmp_path):
    from flakelab.models.checkpoint import TrainingCheckpoint
    from flakelab.models.training import data_hash

    config = replace(QUICK, hidden=(8,), epochs=2, finetune_epochs=1)
    path = tmp_path / "run.ckpt"
    train_protocol(data, config, checkpoint=TrainingCheckpoint(path, config, data_hash(data)))
    assert TrainingCheckpoint(path, config, data_hash(data)).stages == protocol_stages(config)
    with pytest.raises(
        ModelError, match=r"run.ckpt: the checkpoint of another training \(epochs 2, here 3\)"
    ):
        TrainingCheckpoint(path, replace(config, epochs=3), data_hash(data))
    with pytest.raises(
        ModelError, match=r"run.ckpt: the checkpoint of another training \(other cases\)"
    ):
        TrainingCheckpoint(path, config, data_hash(data.subset(np.arange(100))))
    stored = torch.load(path, weights_only=True)
    stored["meta"] = json.dumps(json.loads(stored["meta"]) | {"outliers": [False] * 10})
    torch.save(stored, path)
    with pytest.raises(ModelError, match="keeps the outliers of 10 cases, where the training"):
        train_protocol(data, config, checkpoint=TrainingCheckpoint(path, config, data_hash(data)))
    path.write_bytes(path.read_bytes()[:500])
    with pytest.raises(ModelError, match=r"run.ckpt: not a flakelab training checkpoint \("):
        TrainingCheckpoint(path, config, data_hash(data))


def _fit_side_by_side(data, rows: list, epochs: int) -> list[ForwardModel]:
    models = [_new_model(data, QUICK, r) for r in rows]
    fit(models, data, rows, epochs, 2e-3, QUICK, [], [f"model {k}" for k in range(len(rows))])
    return models


def test_models_trained_side_by_side_train_as_they_would_alone(data):
    """The protocol's fold models share one batched network: model A must come out the same
    whether it trains beside B or beside C, and (one epoch, the same draw) alone."""
    a, b, c = np.arange(0, 200), np.arange(200, 400), np.arange(100, 300)
    with_b = _fit_side_by_side(data, [a, b], epochs=3)[0].predict(data.x[:50])[0]
    with_c = _fit_side_by_side(data, [a, c], epochs=3)[0].predict(data.x[:50])[0]
    np.testing.assert_allclose(with_b, with_c, rtol=1e-5)
    alone = _fit_side_by_side(data, [a], epochs=1)[0].predict(data.x[:50])[0]
    beside = _fit_side_by_side(data, [a, c], epochs=1)[0].predict(data.x[:50])[0]
    untrained = _new_model(data, QUICK, a).predict(data.x[:50])[0]
    np.testing.assert_allclose(alone, beside, rtol=1e-4)
    assert np.abs(alone - untrained).max() > 100 * np.abs(alone - beside).max()


def test_cases_without_texture_readings_teach_no_texture(data):
    """A case whose instrument read no texture adds no texture error: a model that lacks half
    its cases' texture learns texture as one that has all of it, not dragged toward zero."""
    rows, held = np.arange(0, 300), np.arange(300, 400)
    texture = data.texture.copy()
    texture[rows[::2]] = np.nan
    half = replace(data, texture=texture)
    model = _new_model(half, QUICK, rows)
    spectral = model.spectral_outputs
    np.testing.assert_allclose(model.y_mean[spectral:], data.texture[rows[1::2]].mean(0))
    (full,) = _fit_side_by_side(data, [rows], epochs=15)
    (partial,) = _fit_side_by_side(half, [rows], epochs=15)
    full_mae = evaluate_model(full, data.subset(held))["texture_mae"]
    partial_mae = evaluate_model(partial, data.subset(held))["texture_mae"]
    spread = data.texture[held].std(0)
    for k, name in enumerate(TEXTURE_READINGS):
        assert partial_mae[name] < full_mae[name] + 0.25 * spread[k], name
    # held-out cases that read no texture are left out of its error, not counted as zero
    unread = evaluate_model(partial, replace(half.subset(held), texture=np.full((100, 8), np.nan)))
    assert set(unread["texture_mae"].values()) == {None}


def test_robust_outlier_rule():
    errors = np.concatenate([np.random.default_rng(0).normal(1, 0.1, 500), [5.0, 9.0]])
    assert np.flatnonzero(flag_outliers(errors, 6.0)).tolist() == [500, 501]


def test_registry_promotes_only_a_better_model(trained, data, database_url):
    engine = open_database(database_url)
    good, _ = trained
    torch.manual_seed(0)
    worse = ForwardModel.from_bytes(good.to_bytes())
    with torch.no_grad():
        for p in worse.network.parameters():
            p.add_(0.3 * torch.randn_like(p))
    first = register(engine, good, data, name="test")
    second = register(engine, worse, data, name="test")
    assert second["version"] == first["version"] + 1
    assert not second["promoted"] and second["held_out_de00"] > first["held_out_de00"]
    listed = {(m["name"], m["version"]): m for m in list_models(engine)}
    assert listed[("test", second["version"])]["status"] == "candidate"
    # the sizes come from the database, not from reading every artefact
    assert listed[("test", first["version"])]["size_kb"] == round(len(good.to_bytes()) / 1024, 1)


def test_a_version_is_promoted_and_retired_by_hand(trained, data, database_url):
    """A rollback: any registered version is made the current model, the one promoted before
    retired; retiring the promoted one leaves none promoted (the shipped model is current)."""
    engine = open_database(database_url)
    model, _ = trained
    first, second = (register(engine, model, data, name="hand")["version"] for _ in range(2))

    def statuses() -> dict[int, str]:
        return {m["version"]: m["status"] for m in list_models(engine) if m["name"] == "hand"}

    assert promote(engine, "hand", first)["version"] == first
    assert statuses()[first] == "promoted" and statuses()[second] != "promoted"
    assert promote(engine, "hand", second)["retired"] == first
    assert statuses() == {first: "retired", second: "promoted"}
    assert retire(engine, "hand", second)["was"] == "promoted"
    assert promoted_model(engine, "hand") is None
    with pytest.raises(ModelError, match=f"no version 99 of model 'hand' \\(versions {first}, "):
        promote(engine, "hand", 99)


def test_effect_share_floor_is_where_the_effect_paints_of_the_cases_run_out(trained, data):
    model, _ = trained
    share = (data.x * data.effect).sum(1) / data.x.sum(1)
    floor = model.info["effect_share_floor"]
    # the generator's effect paints keep at least a fifth of their weight in effect toners
    # (a white pearl: its pearl beside up to three times as much white)
    assert 0.2 < floor <= np.min(share[share > 0]) + 0.05
    assert np.sum((share > 0) & (share < floor)) <= max(1, 0.001 * share.size)
    x = np.array([[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 0.5, 0.5], [0.02, 0.0, 0.0, 0.98]])
    assert effect_share_floor(x, np.array([1.0, 1.0, 0.0, 0.0])) == pytest.approx(0.02)
    assert effect_share_floor(x[:2], np.array([1.0, 1.0, 0.0, 0.0])) == 0.0  # solids only
    assert effect_share_floor(x, None) == 0.0


@pytest.mark.parametrize("instrument", sorted(SHIPPED))
def test_shipped_models_record_their_effect_share_floor(instrument):
    # the demo cases' effect paints: effect toners are at least ~26 % of a recipe, a white
    # pearl's (~48 % before the cases held white pearls, stop 108)
    assert 0.24 <= shipped_model(instrument).info["effect_share_floor"] <= 0.3


def test_unknown_toner_in_a_recipe_is_an_error(trained):
    model, _ = trained
    with pytest.raises(ModelError, match="unknown"):
        model.fractions([{"Unobtainium": 1.0}])


@pytest.mark.parametrize("instrument", sorted(SHIPPED))
def test_shipped_models_cover_the_demo_library(instrument):
    model = shipped_model(instrument)
    assert model.toners == LIBRARY.names
    assert model.instrument == instrument
    R, texture = model.predict(np.eye(len(LIBRARY.names))[:3])
    assert R.shape == (3, len(model.geometries), 31) and np.all(R > 0)


def test_colour_loss_is_the_mean_squared_cie94_difference(trained, data):
    """The training's colour term against colour-science's CIE 1994 (graphic arts), on
    decoded network outputs; zero when the outputs are the measured data themselves."""
    import colour

    from flakelab.core.colorimetry import reflectance_to_Lab
    from flakelab.models.network import LOG_FLOOR
    from flakelab.models.training import _colour_loss

    model, _ = trained
    # cases the log floor leaves as measured (a carbon-black solid reads below it: its
    # targets are floored, and so are perfect outputs)
    cases = np.flatnonzero(data.R.min(axis=(1, 2)) > 2 * LOG_FLOOR)[:12]
    R, x = data.R[cases], data.x[cases]
    rows = torch.arange(len(cases))[None]
    loss = _colour_loss([model], [R])
    features = model.features(torch.as_tensor(x)).numpy()
    with torch.no_grad():
        output = model.network(torch.as_tensor((features - model.x_mean) / model.x_std).float())
        value = float(loss(output[None], rows)[0])
    predicted, _ = model.predict(x)
    reference = colour.delta_E(
        reflectance_to_Lab(R), reflectance_to_Lab(predicted), method="CIE 1994"
    )
    assert value == pytest.approx(np.mean(reference**2), rel=2e-3)
    perfect = (model.encode_targets(R, data.texture[cases]) - model.y_mean) / model.y_std
    exact = float(loss(torch.as_tensor(perfect, dtype=torch.float32)[None], rows)[0])
    assert exact < 1e-3 * value


def test_colour_loss_stays_finite_for_an_output_far_out(trained, data):
    """An output far beyond any reflectance (a step gone wide) is clipped as a prediction is
    (:func:`~flakelab.models.network.reflectance_from_log`): its loss and gradient stay finite.
    Unclipped, exp overflowed float32 and the NaN took the weights (stop 107)."""
    from flakelab.models.training import _colour_loss

    model, _ = trained
    loss = _colour_loss([model], [data.R[:4]])
    output = torch.zeros(1, 4, model.y_mean.size)
    output[0, 0, 3] = 200.0  # 200 standard deviations: e^(hundreds) before the clip
    output.requires_grad_(True)
    value = loss(output, torch.arange(4)[None])
    value.sum().backward()
    assert torch.isfinite(value).all() and torch.isfinite(output.grad).all()
    assert float(value[0].detach()) > 0


def test_a_training_that_diverges_is_refused_naming_its_stage(data):
    """A loss that is no longer finite loses the weights: the protocol stops there, naming the
    stage and epoch, where it once went on and wrote a model of NaN (stop 107)."""
    wild = replace(QUICK, learning_rate=1e9, epochs=3, finetune_epochs=1)
    with pytest.raises(ModelError, match=r"training diverged: partition 1, epoch \d: the loss"):
        train_protocol(data, wild)


@pytest.mark.parametrize(
    "settings, problem",
    [
        ({"hidden": (0, 5)}, "hidden: expected layer sizes from 1 to 4096"),
        ({"hidden": ()}, "hidden: expected layer sizes from 1 to 4096"),
        # a model its own file would refuse (test_a_model_file_s_description_is_checked…)
        ({"hidden": (100, 5000)}, "hidden: expected layer sizes from 1 to 4096"),
        ({"members": 65}, "members: expected at most 64, got 65"),
        ({"epochs": 0}, "epochs: expected 1 or more, got 0"),
        ({"members": 0}, "members: expected 1 or more"),
        ({"device": "meta"}, "device: expected auto or one of cpu, cuda"),
        ({"device": "gpu"}, "device: expected auto or one of cpu, cuda"),
        ({"device": "cuda:7"}, "device: 'cuda:7' cannot be used here"),
    ],
)
def test_a_training_configuration_that_cannot_train_is_refused(settings, problem):
    """A layer of no units trained to a useless model (``flakelab train --hidden 0,5`` ran 600
    epochs), and no epochs ended in an IndexError after the data were read."""
    with pytest.raises(ModelError, match=problem):
        TrainingConfig(**settings)


def test_the_device_a_model_trained_on_is_not_carried_to_its_adaptation(trained):
    """A model trained on a GPU is adapted on the CPU unless asked: the device is the
    machine's, and a shop without that GPU must still adapt it."""
    model, _ = trained
    on_gpu = replace(model, info=model.info | {"config": model.info["config"] | {"device": "cuda"}})
    assert recorded_config(on_gpu).device == "cpu"
    assert recorded_config(on_gpu).seed == QUICK.seed


def test_a_gpu_this_machine_lacks_is_refused_before_any_work(cli, tmp_path):
    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU")
    result = cli("train", str(tmp_path / "missing.csv"), "--device", "cuda")
    assert result.returncode == 2
    assert "'cuda' cannot be used here" in result.stderr
    assert "missing.csv" not in result.stderr  # refused before the cases are read


def test_cli_a_training_interrupted_goes_on_from_its_checkpoint(cli, tmp_path, monkeypatch, ctrl_c):
    """``train --checkpoint``: a Ctrl-C in the third stage says what the file keeps; the
    same command again goes on from there, writes the model an uninterrupted training
    writes, and removes the file."""
    import flakelab.models.training as training

    cases, checkpoint = tmp_path / "cases.csv", tmp_path / "run.ckpt"
    assert cli("cases", "generate", "--n", "150", "--seed", "3", "--out", cases).returncode == 0
    train = ("train", cases, "--epochs", "2", "--hidden", "8", "--no-register", "--json")
    fit_as_is = training.fit
    monkeypatch.setattr(training, "fit", ctrl_c(fit_as_is, 3))
    run = cli(*train, "--checkpoint", checkpoint, "--out", tmp_path / "a.pt")
    assert run.returncode == 130 and not (tmp_path / "a.pt").exists()
    said = " ".join(run.stderr.split())
    assert f"interrupted: {checkpoint} keeps 2 of the protocol's 10 stages; the same" in said
    monkeypatch.undo()
    run = cli(*train, "--checkpoint", checkpoint, "--out", tmp_path / "a.pt")
    assert run.returncode == 0 and json.loads(run.stdout)["stages_resumed"] == 2
    assert not checkpoint.exists()
    assert cli(*train, "--out", tmp_path / "b.pt").returncode == 0
    assert (tmp_path / "a.pt").read_bytes() == (tmp_path / "b.pt").read_bytes()
    monkeypatch.setattr(training, "fit", ctrl_c(fit_as_is, 3))
    run = cli(*train, "--out", tmp_path / "c.pt")
    assert run.returncode == 130 and "nothing was written or registered" in run.stderr
    monkeypatch.setattr(training, "fit", ctrl_c(fit_as_is, 1))
    run = cli(*train, "--checkpoint", checkpoint)
    assert run.returncode == 130 and not checkpoint.exists()
    assert f"no stage was done: {checkpoint} keeps none" in " ".join(run.stderr.split())


GPU = "cpu" if training_device("auto").type == "cpu" else str(training_device("auto"))
needs_gpu = pytest.mark.skipif(GPU == "cpu", reason="torch sees no GPU here")


@needs_gpu
def test_training_on_a_gpu_matches_the_cpu(data):
    """The batches and starting weights come from the CPU, so one epoch on the GPU gives the
    CPU's model to float rounding, far closer than one epoch moves it; the model comes back
    to the CPU."""
    rows = [np.arange(0, 300)]
    models = {}
    for device in ("cpu", GPU):
        config = replace(QUICK, device=device)
        models[device] = [_new_model(data, config, r) for r in rows]
        fit(models[device], data, rows, 1, 2e-3, config, [], ["model"])
    cpu, gpu = (models[d][0].predict(data.x[:50])[0] for d in ("cpu", GPU))
    untrained = _new_model(data, QUICK, rows[0]).predict(data.x[:50])[0]
    assert {p.device.type for p in models[GPU][0].network.parameters()} == {"cpu"}
    np.testing.assert_allclose(gpu, cpu, rtol=1e-3)
    assert np.abs(cpu - untrained).max() > 100 * np.abs(gpu - cpu).max()


@needs_gpu
def test_the_protocol_and_adaptation_on_a_gpu_reach_the_cpus_accuracy(trained, data):
    """The whole protocol on the GPU: the same outliers, a held-out error within a tenth of
    the CPU's; adaptation with a validation share keeps its best epoch there too."""
    held = np.arange(300, 400)
    train = data.subset(np.arange(300))
    cpu_model, cpu_report = train_protocol(train, QUICK)
    gpu_model, gpu_report = train_protocol(train, replace(QUICK, device=GPU))
    assert gpu_report["outliers"] == cpu_report["outliers"]
    cpu_error = evaluate_model(cpu_model, data.subset(held))["de00_mean"]
    gpu_error = evaluate_model(gpu_model, data.subset(held))["de00_mean"]
    assert abs(gpu_error - cpu_error) < 0.1 * cpu_error
    reports = [
        adapt_model(gpu_model, data.subset(held), replace(QUICK, adapt_epochs=20, device=d))[1]
        for d in ("cpu", GPU)
    ]
    best = [r["validation_de00_best"] for r in reports]
    assert best[1] == pytest.approx(best[0], rel=0.05)
    assert best[1] <= min(e["validation_de00"] for e in reports[1]["log"]) + 1e-9


def test_a_models_card_tells_what_it_learned_from(cli, tmp_path):
    """``flakelab model show``: the shipped model's toners with the cases that taught each;
    the toners it met in no case are those the physics scaling stands in for."""
    run = cli("model", "show", "five-angle", "--json")
    assert run.returncode == 0, run.stderr
    card = json.loads(run.stdout)
    model = shipped_model("five-angle")
    assert card["source"] == "shipped" and card["toners"] == list(model.toners)
    assert card["members"] == model.members and card["geometries"] == list(model.geometries)
    assert card["learned_cases"] is None  # generated cases, no record kept
    unseen = [t for t, n in card["toner_cases"].items() if n == 0]
    assert unseen and sorted(unseen) == sorted(card["novel_toners"])
    for spec, problem in (
        ("nonsense", "MODEL: expected a model file, NAME:VERSION"),
        (str(tmp_path / "m.pt"), "no such model file"),
        (str(tmp_path), "a folder, not a model file"),
        ("byk-mac-i", "no shipped model for 'byk-mac-i'"),
    ):
        run = cli("model", "show", spec)
        assert run.returncode == 2 and problem in run.stderr, (spec, run.stderr)


def _by_colour(data):
    """``data`` with every spray-out known by its colour alone: the spectrum recovered from
    its L*a*b* in D65/10, flagged."""
    from flakelab.core.colorimetry import reflectance_from_Lab, reflectance_to_Lab
    from flakelab.core.measurement import REFLECTANCE_RANGE

    R = reflectance_from_Lab(reflectance_to_Lab(data.R), floor=REFLECTANCE_RANGE[0])
    return replace(data, R=R, colour_alone=np.ones(len(data.case_ids), dtype=bool))


@pytest.mark.slow  # a validation run: three networks trained, 16 s
def test_a_model_trained_afresh_learns_spray_outs_known_by_their_colour_alone():
    """A shop with few measured spray-outs and many known by their L*a*b* alone trains on
    both: spectra from the measured, colour from the others. Beside 200 measured, 600 known
    by colour more than halve the error on fresh cases (9.2 → 4.4 mean ΔE00 at this small
    size and 100 epochs; 2.89 → 1.77 for 1,000 and 2,000 at 300, as 2,000 more measured give
    1.80). Fewer than ten measured spray-outs leave no spectra to learn, and are refused."""
    from flakelab.models.training import evaluate_model, train_protocol

    world = World(read_library(None), "five-angle")
    measured, more, fresh = (generated_case_arrays(world, n, seed)
                             for n, seed in ((200, 11), (600, 12), (400, 13)))  # fmt: skip
    config = TrainingConfig(epochs=100, finetune_epochs=100, hidden=(64, 64), seed=0)
    errors = [
        evaluate_model(train_protocol(data, config)[0], fresh)["de00_mean"]
        for data in (measured, measured.joined(_by_colour(more)))
    ]
    assert errors[1] < 0.6 * errors[0], errors
    few = measured.subset(np.arange(9)).joined(_by_colour(more))
    with pytest.raises(
        ModelError, match="at least 10 measured spray-outs to learn spectra from, got 9"
    ):
        train_protocol(few, config)
