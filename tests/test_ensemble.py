"""Ensembles of the learned model: members trained side by side, averaged, and their spread."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from flakelab.cases.generator import World
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.io import read_library
from flakelab.match.judging import evaluate_recipes, model_spread
from flakelab.match.models import forward_for
from flakelab.match.search import match
from flakelab.models.network import ForwardModel, ModelError
from flakelab.models.registry import shipped_model
from flakelab.models.training import (
    TrainingConfig,
    adapt_model,
    generated_case_arrays,
    protocol_epochs,
    train_protocol,
)
from test_models import SMALL, with_meta

QUICK = TrainingConfig(hidden=(32, 32), epochs=40, finetune_epochs=10, batch_size=16, seed=3)
LIBRARY = read_library(None)


@pytest.fixture(scope="module")
def data():
    return generated_case_arrays(World(SMALL, "five-angle"), 300, seed=5)


@pytest.fixture(scope="module")
def ensemble(data):
    return train_protocol(data, replace(QUICK, members=3))


def _log_reflectance(model: ForwardModel, x: np.ndarray) -> np.ndarray:
    return np.log(model.predict(x)[0])


def test_an_ensemble_predicts_its_members_mean_log_reflectance(ensemble, data):
    model, _ = ensemble
    members = model.split_members()
    assert model.members == 3 and len(members) == 3
    x = data.x[:40]
    mean = np.mean([_log_reflectance(m, x) for m in members], axis=0)
    np.testing.assert_allclose(_log_reflectance(model, x), mean, atol=1e-5)
    # the members are different networks, not one network three times
    assert np.abs(_log_reflectance(members[0], x) - _log_reflectance(members[1], x)).max() > 1e-3


def test_an_ensemble_errs_no_more_than_its_members_on_average(ensemble, data):
    """Jensen: the squared error of the members' mean log reflectance is at most the mean of
    their squared errors, case by case."""
    model, _ = ensemble
    measured = np.log(np.maximum(data.R, 1e-3))
    mean_error = ((_log_reflectance(model, data.x) - measured) ** 2).mean(axis=(1, 2))
    member_errors = [
        ((_log_reflectance(m, data.x) - measured) ** 2).mean(axis=(1, 2))
        for m in model.split_members()
    ]
    assert np.all(mean_error <= np.mean(member_errors, axis=0) + 1e-9)


def test_the_protocol_trains_every_member_on_the_cleaned_cases(ensemble):
    model, report = ensemble
    stages = list(dict.fromkeys(entry["stage"] for entry in report["log"]))
    assert stages[-6:] == ["final 1", "final 2", "final 3"] + [
        f"final {k} fine-tune" for k in (1, 2, 3)
    ]
    assert len(report["log"]) == protocol_epochs(replace(QUICK, members=3))
    assert model.info["config"]["members"] == 3


def test_an_ensemble_survives_a_round_trip_through_bytes(ensemble, data):
    model, _ = ensemble
    again = ForwardModel.from_bytes(model.to_bytes())
    assert again.members == 3 and again.fingerprint == model.fingerprint
    np.testing.assert_allclose(again.predict(data.x[:20])[0], model.predict(data.x[:20])[0])


def test_a_model_file_with_a_wrong_member_count_is_refused(ensemble):
    model, _ = ensemble
    for members, problem in ((2, "weights do not fit"), ("three", "members: expected")):
        with pytest.raises(ModelError, match=f"m.pt: {problem}"):
            ForwardModel.from_bytes(with_meta(model, members=members), source="m.pt")


def test_members_of_another_standardisation_do_not_make_an_ensemble(ensemble, data):
    model, _ = ensemble
    member = model.split_members()[0]
    shifted = replace(member, y_mean=member.y_mean + 0.1)
    with pytest.raises(ModelError, match="standardisation"):
        ForwardModel.ensemble([member, shifted])


def test_an_adapted_ensemble_keeps_its_members_each_at_its_best_epoch(ensemble, data):
    model, _ = ensemble
    config = replace(QUICK, members=3, adapt_epochs=4, adapt_validation=0.25)
    adapted, report = adapt_model(model, data.subset(np.arange(80)), config)
    assert adapted.members == 3 and len(report["member_kept_epochs"]) == 3
    assert {e["stage"] for e in report["log"]} == {"adapt 1", "adapt 2", "adapt 3"}
    # the copy is adapted, not the model it came from
    assert model.fingerprint != adapted.fingerprint or report["member_kept_epochs"] == [0, 0, 0]


@pytest.fixture(scope="module")
def hybrid_ensemble():
    """Two of the shipped ensemble's members as an ensemble of their own, through the hybrid
    path for the demo library's new toners."""
    members = shipped_model("five-angle").split_members()
    return forward_for(ForwardModel.ensemble(members[:2]), LIBRARY)


def test_the_hybrid_members_average_to_the_hybrid_prediction(hybrid_ensemble):
    forward = hybrid_ensemble
    assert forward.novel and forward.members == 2
    x = np.random.default_rng(1).dirichlet(np.full(len(LIBRARY.names), 0.3), 8)
    members = forward.member_reflectance(x)
    R, _ = evaluate_recipes(forward, x)
    np.testing.assert_allclose(np.exp(np.log(members).mean(0)), R, rtol=1e-5)
    spread = model_spread(forward, x, reflectance_to_Lab(R))
    np.testing.assert_allclose(
        spread,
        np.sqrt(np.mean(delta_E(reflectance_to_Lab(R)[None], reflectance_to_Lab(members)) ** 2, 0)),
    )
    assert spread.min() > 0.0


def test_no_spread_where_the_physics_base_takes_over(hybrid_ensemble):
    forward = hybrid_ensemble
    x = np.zeros((1, len(LIBRARY.names)))
    x[0, [LIBRARY.names.index(n) for n in forward.novel]] = 0.5
    members = forward.member_reflectance(x)
    np.testing.assert_allclose(members[0], members[1], rtol=1e-12)


def test_a_single_network_reports_no_spread_and_an_ensemble_does(hybrid_ensemble):
    from flakelab.data import example_path
    from flakelab.io import read_measurement
    from flakelab.match.models import effect_mask

    target = read_measurement(example_path("target"))
    single = forward_for(shipped_model("five-angle").split_members()[0], LIBRARY)
    effect = effect_mask(LIBRARY, single.toners)
    assert model_spread(single, np.eye(len(LIBRARY.names))[:2], np.zeros((2, 5, 3))) is None
    result = match(target, hybrid_ensemble, effect)
    best = result.to_dict()["candidates"][0]
    assert all(v["model_spread"] > 0 for v in best["geometries"].values())


def test_fitting_an_ensemble_as_one_network_is_refused(ensemble, data):
    from flakelab.models.training import fit

    model, _ = ensemble
    with pytest.raises(ModelError, match="ensemble of 3 networks.*split_members"):
        fit([model], data, [np.arange(10)], 1, 1e-3, QUICK, [], ["a"])


def test_the_model_risk_is_the_members_rms_cie94_from_their_mean(hybrid_ensemble):
    """The matcher's model-risk term, in torch, against colour-science's CIE 1994 on the
    numpy path, for recipes without new toners (where the learned members are the whole
    prediction) and the single-network case, where it has nothing to measure."""
    import colour

    from flakelab.core.torch_colour import TorchColour
    from flakelab.match.search import model_risk

    forward = hybrid_ensemble
    known = np.array([n not in forward.novel for n in LIBRARY.names])
    x = np.random.default_rng(2).dirichlet(np.full(known.sum(), 0.3), 6)
    x_full = np.zeros((6, len(LIBRARY.names)))
    x_full[:, known] = x
    members = forward.member_reflectance(x_full)
    mean_lab = reflectance_to_Lab(evaluate_recipes(forward, x_full)[0])
    de94 = colour.delta_E(mean_lab[None], reflectance_to_Lab(members), method="CIE 1994")
    expected = np.sqrt(np.mean(de94**2, axis=0)).mean(axis=1)
    colour_t = TorchColour(dtype=forward.dtype)
    R, _, members_t = forward.with_members(torch.as_tensor(x_full, dtype=forward.dtype))
    np.testing.assert_allclose(R.numpy(), evaluate_recipes(forward, x_full)[0], rtol=1e-5)
    risk = model_risk(colour_t, members_t)
    np.testing.assert_allclose(risk.numpy(), expected, rtol=2e-3, atol=2e-3)
    assert expected.min() > 0.01
    single = forward_for(shipped_model("five-angle").split_members()[0], LIBRARY)
    alone = model_risk(colour_t, single.with_members(torch.as_tensor(x_full))[2])
    assert alone.abs().max() < 2e-3  # one member: no disagreement but the root's floor


def test_the_objective_adds_the_weighed_model_risk_for_an_ensemble_only(hybrid_ensemble):
    """The search's objective with ``model_risk`` w is the colour objective plus w times the
    members' disagreement, through the hybrid path too (recipes with a new toner); a single
    network's objective is left as it was."""
    from flakelab.data import example_path
    from flakelab.io import read_measurement
    from flakelab.match.objective import MatchObjective
    from flakelab.match.search import MatchSettings, _loss, model_risk, target_spectra

    colour_t = MatchObjective(hybrid_ensemble.geometries, dtype=hybrid_ensemble.dtype)
    single = forward_for(shipped_model("five-angle").split_members()[0], LIBRARY)
    spectra, _, _ = target_spectra(read_measurement(example_path("target")), hybrid_ensemble)
    target_lab = colour_t.lab(torch.as_tensor(spectra, dtype=hybrid_ensemble.dtype))
    x = np.random.default_rng(3).dirichlet(np.full(len(LIBRARY.names), 0.3), 6)
    x = torch.as_tensor(x, dtype=hybrid_ensemble.dtype)
    assert x[:, [LIBRARY.names.index(n) for n in hybrid_ensemble.novel]].min() > 0

    def objective(forward, weight):
        return _loss(forward, colour_t, x, target_lab, None, MatchSettings(model_risk=weight))

    risk = model_risk(colour_t, hybrid_ensemble.with_members(x)[2])
    added = objective(hybrid_ensemble, 2.0) - objective(hybrid_ensemble, 0.0)
    np.testing.assert_allclose(added.numpy(), 2.0 * risk.numpy(), rtol=1e-4)
    assert risk.min() > 0.01
    np.testing.assert_array_equal(objective(single, 2.0).numpy(), objective(single, 0.0).numpy())


def test_the_folded_network_computes_what_its_layers_do(ensemble, data):
    """Standardise, run each member, de-standardise, average (:meth:`member_outputs`): the
    folded network's one pass gives the same outputs and the same gradients with respect to
    the recipe, which the matcher descends."""
    model, _ = ensemble
    x = torch.tensor(data.x[:40], dtype=torch.float32, requires_grad=True)
    layer_by_layer = model.member_outputs(x).mean(dim=0)
    folded = model.folded()(x)
    torch.testing.assert_close(folded, layer_by_layer, atol=1e-4, rtol=1e-5)
    weights = torch.linspace(-1, 1, folded.shape[1])  # every output's gradient counts
    (by_layers,) = torch.autograd.grad((layer_by_layer * weights).sum(), x)
    (by_fold,) = torch.autograd.grad((folded * weights).sum(), x)
    torch.testing.assert_close(by_fold, by_layers, atol=1e-4, rtol=1e-4)


def test_prediction_in_batches_is_prediction_at_once(ensemble, data):
    model, _ = ensemble
    R, texture = model.predict(data.x[:50])
    R_batched, texture_batched = model.predict(data.x[:50], batch=7)
    # float32 sums in another order: the last digits may differ
    np.testing.assert_allclose(R_batched, R, rtol=2e-5)
    np.testing.assert_allclose(texture_batched, texture, rtol=2e-5, atol=1e-5)
    members = model.predict_members(data.x[:50], batch=7)
    assert members.shape == (3, *R.shape)
    np.testing.assert_allclose(np.log(members).mean(axis=0), np.log(R), atol=1e-5)
