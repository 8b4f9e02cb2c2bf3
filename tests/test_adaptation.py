"""The protocol's adaptation phase: a trained model taught one shop's habits."""

from __future__ import annotations

import copy
from dataclasses import replace

import numpy as np
import pytest

from flakelab.cases.generator import SHOP_WITH_HABITS, World, WorldSettings
from flakelab.io import read_library
from flakelab.match.habits import estimate_habits
from flakelab.match.models import forward_for
from flakelab.models.network import ModelError
from flakelab.models.registry import shipped_model
from flakelab.models.training import (
    adapt_model,
    adapt_to_shop,
    adaptation_cases,
    evaluate_model,
    fit,
    generated_case_arrays,
    outlying_cases,
    recorded_config,
    withhold_for_adaptation,
)

SHOP_HABITS = WorldSettings(**SHOP_WITH_HABITS)


@pytest.fixture(scope="module")
def model():
    return shipped_model("five-angle")


def shop_cases(model, settings: WorldSettings, n: int, seed: int):
    library = read_library(None)
    world = World(library, "five-angle", settings, exclude=model.new_toners)
    return generated_case_arrays(world, n, seed, shop="shop A")


def test_a_shops_habits_are_drawn_about_its_own_means():
    world = World(read_library(None), "five-angle", SHOP_HABITS)
    rng = np.random.default_rng(3)
    n = 20000
    film, spread = world.application(n, rng)
    factory_film, factory_spread = world.application(n, rng, at_shop=False)
    assert film.mean() == pytest.approx(1.05, abs=4 * 0.04 / n**0.5)
    assert np.exp(np.log(spread).mean()) == pytest.approx(0.96, rel=4 * 0.02 / n**0.5)
    assert factory_film.mean() == pytest.approx(1.0, abs=4 * 0.04 / n**0.5)
    assert np.exp(np.log(factory_spread).mean()) == pytest.approx(1.0, rel=4 * 0.02 / n**0.5)
    R = np.full((n, 5, 31), 0.4)
    # the instrument's gain on top of its per-reading gain error (mean zero)
    assert world.measure(R, rng).mean() / 0.4 == pytest.approx(1.005, abs=2e-4)


@pytest.mark.slow  # a validation run: a model adapted to 600 cases, 9 s
def test_adaptation_learns_a_shops_habits(model):
    train = shop_cases(model, SHOP_HABITS, 600, 21)
    fresh = shop_cases(model, SHOP_HABITS, 400, 22)
    config = replace(recorded_config(model), seed=1)
    adapted, report = adapt_model(model, train, config, shop="shop A")
    before = evaluate_model(model, fresh)["de00_mean"]
    after = evaluate_model(adapted, fresh)["de00_mean"]
    # the shipped model sees the shop's paints about 0.4 ΔE00 off; after: within about 0.1
    # of what it scores in the world it learned (0.68)
    assert before > 1.0 and after < before - 0.25
    assert report["validation_cases"] == 120 and 0 < report["kept_epochs"] <= 150
    assert adapted.info["adaptation"]["cases"] == 480
    assert adapted.info["adaptation"]["shop"] == "shop A"
    assert adapted.info["adaptation"]["from"] == model.identity != adapted.identity
    # the copy is adapted, not the model it came from
    assert evaluate_model(model, fresh)["de00_mean"] == before

    # the shop's habits read against the model it came from: the adapted model has learned
    # them, and adding them again costs about what adapting bought
    library = read_library(None)
    base, learned = forward_for(model, library), forward_for(adapted, library)
    assert "adapted to shop A" in learned.name and "adapted" not in base.name  # as reported
    habits = estimate_habits(base, library, train.x, train.R)
    twice = evaluate_model(adapted, fresh, lab_offset=lambda x, R: habits.offset(
        library, x, R, learned.geometries))["de00_mean"]  # fmt: skip
    assert twice > after + 0.2
    assert habits.learned_by(learned) and not habits.learned_by(base)
    # adapted to the shop: whatever model the habits were read against; not another shop's
    assert replace(habits, model="an older model", shop="shop A").learned_by(learned)
    assert not replace(habits, model="an older model", shop="shop B").learned_by(learned)
    # read against the adapted model itself, they are what it has not learned: added
    assert not estimate_habits(learned, library, train.x, train.R).learned_by(learned)


def test_the_cases_that_choose_the_adaptations_epoch_are_withheld_from_training(model):
    """train --adapt: a share of the shop's cases is withheld from the general training and
    chooses the epoch of the adaptation (cases the model learned would judge every epoch worse
    than none); a mix-up among them is screened out, not allowed to choose."""
    library = read_library(None)
    others = World(library, "five-angle", WorldSettings(), exclude=model.new_toners)
    data = shop_cases(model, SHOP_HABITS, 300, 24).joined(
        generated_case_arrays(others, 100, 25, shop="shop B")
    )
    config = replace(recorded_config(model), seed=2)
    rest, validation = withhold_for_adaptation(data, "shop A", config)
    assert set(validation.shops) == {"shop A"} and len(validation.case_ids) == 60
    assert not set(validation.case_ids) & set(rest.case_ids)
    assert sorted(rest.case_ids + validation.case_ids) == sorted(data.case_ids)
    validation = replace(validation, R=validation.R.copy())
    validation.R[:2] = 0.85  # white panels recorded as two spray-outs
    adapted, report = adapt_to_shop(model, rest, "shop A", config, validation=validation)
    assert report["validation_outlier_case_ids"] == list(validation.case_ids[:2])
    assert (report["cases"], report["validation_cases"]) == (240, 58)
    assert adapted.adaptation["shop"] == "shop A" and adapted.adaptation["from"] == model.identity
    fresh = shop_cases(model, SHOP_HABITS, 300, 26)
    before, after = (evaluate_model(m, fresh)["de00_mean"] for m in (model, adapted))
    assert after < before - 0.25


def test_an_adaptation_is_judged_and_chosen_only_on_cases_the_model_never_learned(model):
    """A model trained on a database, adapted to one shop's cases of it: those it learned are
    adapted on but neither held out nor choosing the epoch (its error on them flatters it)."""
    cases = shop_cases(model, SHOP_HABITS, 300, 27)
    config = replace(recorded_config(model), seed=3)
    learn, choose, held = adaptation_cases(model, cases, 0.1, config)  # it learned none
    assert choose is None and len(learn.case_ids) + len(held.case_ids) == 300
    trained = replace(model, learned=None)
    trained.add_learned(cases.case_ids[:200])
    learn, choose, held = adaptation_cases(trained, cases, 0.1, config)
    assert not set(held.case_ids + choose.case_ids) & set(cases.case_ids[:200])
    assert set(cases.case_ids[:200]) <= set(learn.case_ids)
    assert sorted(learn.case_ids + choose.case_ids + held.case_ids) == sorted(cases.case_ids)
    assert len(choose.case_ids) == round(0.2 * (100 - len(held.case_ids)))
    trained.add_learned(cases.case_ids)
    with pytest.raises(ModelError, match="learned from all 300 of these cases"):
        adaptation_cases(trained, cases, 0.1, config)
    assert model.learned is None  # the shipped model untouched


def test_mixed_up_sprayouts_among_a_shops_cases_are_flagged_before_adapting(model):
    """Three white panels given as spray-outs among 400 cases of the habits shop: the three
    are flagged, none of the shop's own, however far its habits move them (the screen is
    against the shop's own spread of errors)."""
    cases = shop_cases(model, SHOP_HABITS, 400, 23)
    mixed = replace(
        cases,
        x=np.concatenate([cases.x, cases.x[:3]]),
        R=np.concatenate([cases.R, np.full((3, *cases.R.shape[1:]), 0.85)]),
        texture=np.concatenate([cases.texture, cases.texture[:3]]),
    )
    threshold = recorded_config(model).outlier_threshold
    np.testing.assert_array_equal(np.flatnonzero(outlying_cases(model, mixed, threshold)),
                                  [400, 401, 402])  # fmt: skip


def test_keeping_the_best_epoch_never_leaves_the_model_worse_where_it_is_judged(model):
    # a shop with no habits of its own: its cases teach nothing the model lacks, and all 150
    # epochs fit their noise (one network: the shipped ensemble's first)
    model = model.split_members()[0]
    cases = shop_cases(model, WorldSettings(), 500, 31)
    fresh = shop_cases(model, WorldSettings(), 400, 32)
    train, validation = np.arange(400), np.arange(400, 500)
    config = recorded_config(model)
    held = cases.subset(validation)
    start = evaluate_model(model, held)["de00_mean"]
    kept_model, every_epoch = copy.deepcopy(model), copy.deepcopy(model)
    log: list[dict] = []
    kept = fit([kept_model], cases, [train], 150, 2e-4, config, log, ["a"], validation=[validation])
    fit([every_epoch], cases, [train], 150, 2e-4, config, [], ["a"])
    scores = [entry["validation_de00"] for entry in log]
    best = min([start, *scores])
    assert evaluate_model(kept_model, held)["de00_mean"] == pytest.approx(best, rel=1e-5)
    assert best <= start
    epochs, kept_scores = kept
    assert epochs[0] == (0 if best == start else 1 + int(np.argmin(scores)))
    assert kept_scores[0] == pytest.approx(best, rel=1e-5)
    untouched = evaluate_model(model, fresh)["de00_mean"]
    assert evaluate_model(every_epoch, fresh)["de00_mean"] > untouched + 0.03
    assert evaluate_model(kept_model, fresh)["de00_mean"] < untouched + 0.01


def test_too_few_cases_to_choose_the_epoch_is_an_error(model):
    cases = shop_cases(model, SHOP_HABITS, 3, 41)
    with pytest.raises(ModelError, match="too few"):
        adapt_model(model, cases, replace(recorded_config(model), adapt_validation=0.1))
    with pytest.raises(ModelError, match=r"adapt_validation.*\[0, 1\)"):
        adapt_model(model, cases, replace(recorded_config(model), adapt_validation=1.0))


def test_without_validation_every_epoch_runs(model):
    cases = shop_cases(model, SHOP_HABITS, 40, 42)
    config = replace(recorded_config(model), adapt_validation=0.0, adapt_epochs=3)
    _, report = adapt_model(model, cases, config)
    assert report["kept_epochs"] == 3 and report["validation_cases"] == 0
    # every member of the shipped ensemble runs every epoch
    stages = [f"adapt {k + 1}" for k in range(model.members)] if model.members > 1 else ["adapt"]
    for stage in stages:
        assert [e["epoch"] for e in report["log"] if e["stage"] == stage] == [0, 1, 2]
    assert len(report["log"]) == 3 * model.members


def test_cases_with_the_model_s_new_toners_are_refused(model):
    """A toner the model learned from too few cases standardises to inputs hundreds of s.d.
    out: adapting on such cases blew the weights up to NaN. Now it is refused, naming it."""
    world = World(read_library(None), "five-angle")
    data = generated_case_arrays(world, 40, seed=9)
    used = {t for t, column in zip(data.toners, data.x.T, strict=True) if column.any()}
    new = [t for t in model.new_toners if t in used]
    assert new  # the seed draws some
    with pytest.raises(ModelError, match=f"too few cases \\({', '.join(new)}\\)"):
        adapt_model(model, data)


def test_a_toner_met_in_too_few_cases_is_new_without_being_declared(model):
    """A model trained by ``flakelab train`` declares no new toners; those it met in fewer
    than ``MIN_CASES`` cases are new all the same. Adaptation and the model card read them
    from its record of cases per toner, as the matcher does: they read the shipped models'
    declared list alone, so a model that met a toner in 19 cases was adapted on its cases."""
    from flakelab.models.network import MIN_CASES
    from flakelab.models.registry import model_card

    rare = "Perylene maroon"
    info = {k: v for k, v in model.info.items() if k != "novel_toners"}
    info["toner_cases"] = {**info["toner_cases"], rare: MIN_CASES - 1}
    trained = replace(model, info=info)
    assert set(trained.new_toners) == {rare, *model.new_toners}
    assert rare in model_card(trained)["novel_toners"]
    world = World(read_library(None), "five-angle", exclude=model.new_toners)
    data = generated_case_arrays(world, 60, seed=9)
    assert data.x[:, data.toners.index(rare)].any()  # the seed draws it
    with pytest.raises(ModelError, match=f"too few cases \\({rare}\\)"):
        adapt_model(trained, data)


def test_the_kept_epoch_is_told_with_the_cases_that_chose_it():
    """Epoch 0 is the model as it was, and the cases that chose it are named whether the
    command or the adaptation held them out (``model adapt`` said nothing of them when the
    adaptation split them off itself)."""
    from flakelab.cli.models import _kept_epoch_text

    summary = {"kept_epochs": 0, "epochs": 150, "validation_cases": 8}
    assert _kept_epoch_text(summary) == (
        "kept the model as it was: none of its 150 epochs did better on the 8 cases held out "
        "to choose"
    )
    summary |= {"kept_epochs": 146, "validation_cases": 40}
    assert _kept_epoch_text(summary) == "kept epoch 146 of 150 (chosen on 40 cases)"
    summary |= {"kept_epochs": 150, "validation_cases": 0}
    assert _kept_epoch_text(summary) == "kept epoch 150 of 150"


def test_the_adaptations_progress_counts_its_cases_as_its_report_does():
    """The bar counted the cases that choose the epoch among those adapted on (39 against
    the report's 31) where the adaptation split them off itself."""
    from types import SimpleNamespace

    from flakelab.cli.models import _adapting_label
    from flakelab.models.training import TrainingConfig

    cases = SimpleNamespace(x=np.zeros((39, 3)))
    config = TrainingConfig(adapt_validation=0.2)
    assert _adapting_label(cases, None, config) == "adapting to 31 cases (8 more choose the epoch)"
    withheld = SimpleNamespace(x=np.zeros((10, 3)))
    assert _adapting_label(cases, withheld, config).startswith("adapting to 39 cases (10 more")
    every_epoch = replace(config, adapt_validation=0.0)
    assert _adapting_label(cases, None, every_epoch) == "adapting to 39 cases"


def _known_by_colour(data, seed: int = 0):
    """``data`` with every spray-out known by its colour alone: its spectrum a metamer in
    D65/10 of the one read, another shape each seed (a metameric black of CIE 15's weights
    added, where ``seed`` > 0), flagged as recovered."""
    from flakelab.core.colorimetry import (
        reflectance_from_Lab,
        reflectance_to_Lab,
        tristimulus_weights,
    )
    from flakelab.core.measurement import REFLECTANCE_RANGE

    R = reflectance_from_Lab(reflectance_to_Lab(data.R), floor=REFLECTANCE_RANGE[0])
    if seed:
        weights = tristimulus_weights()  # [31, 3]
        blacks = np.linalg.svd(weights.T)[2][3:]  # [28, 31]: spectra no observer sees in D65/10
        black = np.random.default_rng(seed).normal(size=blacks.shape[0]) @ blacks
        R = R + 0.5 * R.min(axis=-1, keepdims=True) * black / np.abs(black).max()
    return replace(data, R=R, colour_alone=np.ones(len(data.case_ids), dtype=bool))


@pytest.mark.slow  # a validation run: five adaptations, 7 s
def test_spray_outs_known_by_their_colour_alone_teach_a_model_that_colour(model):
    """A shop whose instrument exports L*a*b* alone adapts the model to its habits from its
    colour: the spectrum learned is not the recovered one (a metamer of many) but its colour in
    D65/10 (the loss's colour term). So it gains about what measured spectra gain on fresh
    cases of the shop (stop 115's model: 0.977 → 0.805 against 0.829 from 150 cases; stop
    109's 0.999 → 0.730 against 0.732: ``benchmarks/colour_alone.py --shop``), and two
    metamers teach the same model where, learnt as measured spectra, they teach two."""
    from flakelab.core.colorimetry import reflectance_to_Lab
    from flakelab.core.difference import delta_E

    train = shop_cases(model, SHOP_HABITS, 150, 31)
    fresh = shop_cases(model, SHOP_HABITS, 300, 32)
    config = replace(recorded_config(model), seed=1, adapt_epochs=60)
    one, other = _known_by_colour(train, 1), _known_by_colour(train, 2)
    assert delta_E(reflectance_to_Lab(one.R), reflectance_to_Lab(train.R)).max() < 1e-3
    assert np.abs(one.R - other.R).max() > 0.02  # metamers, not one spectrum
    before = evaluate_model(model, fresh)["de00_mean"]
    measured = evaluate_model(adapt_model(model, train, config)[0], fresh)["de00_mean"]
    adapted = [adapt_model(model, data, config)[0] for data in (one, other)]
    by_colour = evaluate_model(adapted[0], fresh)["de00_mean"]
    assert before > 0.9 and by_colour < before - 0.15 and abs(by_colour - measured) < 0.05
    predicted = [m.predict(fresh.x)[0] for m in adapted]
    assert np.abs(predicted[0] - predicted[1]).max() < 1e-4
    as_measured = [
        adapt_model(model, replace(data, colour_alone=None), config)[0] for data in (one, other)
    ]
    apart = np.abs(as_measured[0].predict(fresh.x)[0] - as_measured[1].predict(fresh.x)[0])
    assert apart.max() > 0.01


def test_spray_outs_known_by_their_colour_alone_need_the_colour_term(model):
    data = _known_by_colour(shop_cases(model, SHOP_HABITS, 40, 33))
    config = replace(recorded_config(model), colour_weight=0.0, adapt_validation=0.0)
    with pytest.raises(ModelError, match="colour term alone; expected a colour_weight above 0"):
        adapt_model(model, data, config)
