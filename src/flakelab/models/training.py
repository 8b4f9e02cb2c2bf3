"""Training protocol of the hybrid paper (DESIGN.md §5) and held-out evaluation.

The loss is the mean squared standardised error of the outputs (log reflectance, texture) plus
``colour_weight`` × the mean squared CIE94 colour difference between predicted and measured
CIELAB at every geometry. Without the colour term the standardisation weights each output by
the inverse of its spread over the cases, which under-weights the bright near-specular
angles, where the eye (and ΔE00) is most sensitive and where the spread is largest. A
spray-out known by its L*a*b* alone (an instrument that exports colour, its spectrum recovered:
one metamer of many) is learnt by the colour term alone, its spectral outputs left out of the
first term as a texture its instrument did not read; its colour in D65/10 is the reading's.
Two metamers of it teach the same model (``tests/test_adaptation.py -k colour_alone``).

1. Split the cases into five partitions (seeded).
2. Screen (``screening``):
   * ``"sequential"``, the paper's: "four of these subsets serve sequentially for model
     training, with each training session comprising 300 epochs [...] followed by an
     additional 300 fine-tuning epochs with reduced learning rates. The fifth part functions
     as a validation set, enabling identification and removal of [...] statistical
     outliers." One model trains on the first four partitions in turn (a session of
     ``epochs`` at ``learning_rate`` then ``finetune_epochs`` at ``finetune_learning_rate``
     on each); its errors on the fifth, which it never saw, set what an ordinary case's
     error is, and every case is judged against them.
   * ``"cross-validation"``: for each partition in turn, a model trains on the other four
     (one session on all four) and judges the held partition, so that every case is judged
     by a model that never saw it; five times the sequential screen's work. The five fold
     models train side by side in one batched network (:func:`fit`), each as it would alone.
3. Flag statistical outliers: a case whose error (mean ΔE00 over geometries) lies more than
   ``outlier_threshold`` robust standard deviations (median/MAD of the judging errors) above
   their median.
4. Train the final model on the cleaned cases (one session).
5. Optionally adapt it to one shop or instrument (``adapt_epochs`` on that shop's cases at
   ``adapt_learning_rate``; :func:`adapt`): a copy of the model, which records the model it
   came from and the shop, by :func:`adapt_to_shop` right after training, or
   :func:`adapt_model` for any model already trained, such as the shipped one. The paper
   runs all 150 epochs; a shop with a few thousand cases is fitted too closely by them
   (``benchmarks/adaptation.py``), so by default ``adapt_validation`` of the shop's cases
   are held out and the model keeps the epoch that predicts them best, its starting weights
   included: adaptation never leaves it worse there than it found it.
   ``adapt_validation=0`` runs the paper's phase as written. Before it, the shop's cases are
   screened, by step 3's screen or, for a model already trained, as in step 3 by the
   model's own error (:func:`outlying_cases`): a mix-up (another panel's reading recorded
   as the spray-out) would otherwise land in the validation or held-out cases and judge the
   adaptation. A model records the cases it learned from (:attr:`ForwardModel.learned`);
   they are adapted on but never judge it nor choose its epoch (:func:`adaptation_cases`,
   :func:`withhold_for_adaptation`): its error on them flatters it, and every epoch would
   judge worse than none.

Training runs on ``device`` (a GPU where torch has one); the batches are drawn and the
networks initialised on the CPU, so a seed gives the same data order and starting weights on
any device, and the trained model returns to the CPU.
"""

from __future__ import annotations

import copy
import functools
import hashlib
import importlib.util
import time
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, fields, replace

import numpy as np
import torch
from numpy.typing import NDArray

from flakelab.cases.case import Case
from flakelab.cases.generator import World
from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E
from flakelab.core.geometry import instrument_of
from flakelab.core.measurement import TEXTURE_READINGS
from flakelab.core.torch_colour import TorchColour
from flakelab.core.wording import counted
from flakelab.errors import Note
from flakelab.library import did_you_mean
from flakelab.models.checkpoint import TrainingCheckpoint
from flakelab.models.network import (
    MAX_HIDDEN,
    MAX_MEMBERS,
    ForwardModel,
    ModelError,
    StackedNetwork,
    build_network,
    reflectance_from_log,
)

__all__ = [
    "generated_case_arrays",
    "TrainingConfig",
    "CaseArrays",
    "case_arrays",
    "train_protocol",
    "protocol_stages",
    "fit",
    "fold_rows",
    "evaluate_model",
    "prediction_errors",
    "error_summary",
    "PredictionErrors",
    "flag_outliers",
    "outlying_cases",
    "data_hash",
    "SCREENINGS",
    "protocol_epochs",
    "adapt",
    "adapt_model",
    "adapt_to_shop",
    "adaptation_cases",
    "adaptation_split",
    "held_out_split",
    "unseen_by",
    "withhold_for_adaptation",
    "recorded_config",
    "training_device",
]

SCREENINGS = ("sequential", "cross-validation")
"""How the protocol finds outliers before the final training (module notes, step 2)."""


@dataclass(frozen=True)
class TrainingConfig:
    hidden: tuple[int, ...] = (100, 100, 100)
    epochs: int = 300
    finetune_epochs: int = 300
    learning_rate: float = 2e-3
    finetune_learning_rate: float = 2e-4
    batch_size: int = 128
    colour_weight: float = 0.02
    folds: int = 5
    screening: str = "sequential"
    outlier_threshold: float = 6.0
    adapt_epochs: int = 150
    adapt_learning_rate: float = 2e-4
    adapt_validation: float = 0.2
    members: int = 1
    log_offset: float = 0.0
    seed: int = 0
    device: str = "cpu"

    def __post_init__(self) -> None:
        training_device(self.device)
        # the limits a model file is read with: what trains here loads everywhere
        if not self.hidden or any(not 1 <= size <= MAX_HIDDEN for size in self.hidden):
            raise ModelError(
                f"hidden: expected layer sizes from 1 to {MAX_HIDDEN}, got {self.hidden}"
            )
        if self.members > MAX_MEMBERS:
            raise ModelError(f"members: expected at most {MAX_MEMBERS}, got {self.members}")
        for name in ("epochs", "finetune_epochs", "batch_size", "folds", "members"):
            if getattr(self, name) < 1:
                raise ModelError(f"{name}: expected 1 or more, got {getattr(self, name)}")

    @classmethod
    def per_stage(cls, epochs: int, learning_rate: float, **settings) -> TrainingConfig:
        """``epochs`` for training and for fine-tuning, which runs at a tenth of
        ``learning_rate`` (the defaults' ratio)."""
        return cls(
            epochs=epochs,
            finetune_epochs=epochs,
            learning_rate=learning_rate,
            finetune_learning_rate=learning_rate / 10,
            **settings,
        )


TRAINING_DEVICE_TYPES = ("cpu", "cuda", "mps", "xpu")
"""Devices torch trains on (CUDA also names AMD's ROCm builds)."""


def training_device(name: str) -> torch.device:
    """The torch device called ``name`` (``"cpu"``, ``"cuda"``, ``"cuda:1"``, ``"mps"``…), or
    for ``"auto"`` the first GPU torch can use, else the CPU; refused when this machine or
    this build of torch has no such device."""
    if name == "auto":
        if torch.cuda.is_available():
            return torch.device("cuda")
        return torch.device("mps" if torch.backends.mps.is_available() else "cpu")
    try:
        device = torch.device(name)
    except RuntimeError:
        device = None
    if device is None or device.type not in TRAINING_DEVICE_TYPES:
        raise ModelError(
            f"device: expected auto or one of {', '.join(TRAINING_DEVICE_TYPES)} (cuda:N for "
            f"the N-th GPU), got {name!r}"
        )
    seen = _devices_seen()
    if device.type not in {d.split(":")[0] for d in seen}:
        detail = f"no {device.type.upper()} device"
    else:
        try:
            torch.empty(1, device=device)
            return device
        except (RuntimeError, AssertionError) as error:  # a GPU index past the last
            detail = str(error).strip().splitlines()[0][:200]
    raise ModelError(
        f"device: {name!r} cannot be used here ({detail}); torch {torch.__version__} sees "
        + ", ".join(seen)
    )


def _devices_seen() -> list[str]:
    cuda = [f"cuda:{i}" for i in range(torch.cuda.device_count())]
    xpu = hasattr(torch, "xpu") and torch.xpu.is_available()
    return [
        "cpu",
        *cuda,
        *(["mps"] if torch.backends.mps.is_available() else []),
        *(["xpu"] if xpu else []),
    ]


@dataclass(frozen=True)
class CaseArrays:
    """Recipes ``x[N, T]``, spray-out reflectance ``R[N, G, 31]``, texture ``tex[N, 8]``
    (NaN where a case's instrument gave no such reading); where any case records the tins its
    recipe was poured from, their ``strength[N, T]`` and ``shade[N, T]`` [nm] (1 and 0 for a
    toner without a recorded tin: the standard, as far as the shop knew); ``colour_alone[N]``,
    which cases know their spray-out by its colour alone (None where none does): their ``R``
    was recovered from their L*a*b* in D65/10, one metamer of many, and is learnt for that
    colour alone (module notes)."""

    x: NDArray
    R: NDArray
    texture: NDArray
    case_ids: tuple[str, ...]
    shops: tuple[str, ...]
    toners: tuple[str, ...]
    geometries: tuple[str, ...]
    instrument: str
    effect: NDArray | None = None
    strength: NDArray | None = None
    shade: NDArray | None = None
    colour_alone: NDArray | None = None

    @property
    def tins_recorded(self) -> NDArray[np.bool_]:
        """Which cases record a tin off the standard ``[N]`` (one read at the standard
        predicts as none)."""
        if self.strength is None:
            return np.zeros(len(self.case_ids), dtype=bool)
        return ((self.strength != 1) | (self.shade != 0)).any(axis=1)

    def recorded_tins_only(self) -> CaseArrays:
        """These cases without tin arrays where none records a tin off the standard."""
        return self if self.tins_recorded.any() else self.without_tins()

    def without_tins(self) -> CaseArrays:
        """These cases as if no tin were recorded: every toner at the standard."""
        return replace(self, strength=None, shade=None)

    def subset(self, rows: NDArray) -> CaseArrays:
        """The cases at ``rows``."""
        return replace(
            self,
            strength=None if self.strength is None else self.strength[rows],
            shade=None if self.shade is None else self.shade[rows],
            colour_alone=None if self.colour_alone is None else self.colour_alone[rows],
            x=self.x[rows],
            R=self.R[rows],
            texture=self.texture[rows],
            case_ids=tuple(self.case_ids[i] for i in rows),
            shops=tuple(self.shops[i] for i in rows),
        )

    def joined(self, other: CaseArrays) -> CaseArrays:
        """These cases, then ``other``'s, of the same toners and geometries."""
        if (other.toners, other.geometries) != (self.toners, self.geometries):
            raise ModelError("cases: expected the same toners and geometries to join them")
        tins = self.strength is not None or other.strength is not None
        (strength, shade), (other_strength, other_shade) = self.tins(), other.tins()
        by_colour = self.colour_alone is not None or other.colour_alone is not None
        return replace(
            self,
            strength=np.concatenate([strength, other_strength]) if tins else None,
            shade=np.concatenate([shade, other_shade]) if tins else None,
            colour_alone=np.concatenate([self.known_by_colour, other.known_by_colour])
            if by_colour
            else None,
            x=np.concatenate([self.x, other.x]),
            R=np.concatenate([self.R, other.R]),
            texture=np.concatenate([self.texture, other.texture]),
            case_ids=self.case_ids + other.case_ids,
            shops=self.shops + other.shops,
        )

    @property
    def known_by_colour(self) -> NDArray[np.bool_]:
        """Which cases know their spray-out by its colour alone ``[N]``."""
        if self.colour_alone is None:
            return np.zeros(len(self.case_ids), dtype=bool)
        return self.colour_alone

    def tins(self) -> tuple[NDArray, NDArray]:
        """``strength[N, T]`` and ``shade[N, T]``, the standard's where none is recorded."""
        if self.strength is None:
            return np.ones_like(self.x), np.zeros_like(self.x)
        return self.strength, self.shade

    def shop_rows(self, shop: str) -> NDArray:
        """The rows of ``shop``'s cases."""
        return np.flatnonzero(np.array(self.shops) == shop)

    def of_shop(self, shop: str) -> CaseArrays:
        """The cases of ``shop``."""
        return self.subset(self.shop_rows(shop))

    def without_toners(self, toners: Iterable[str]) -> CaseArrays:
        """The cases whose recipes hold none of ``toners``."""
        named = np.isin(np.array(self.toners), sorted(toners))
        return self.subset(np.flatnonzero(~(self.x[:, named] > 0).any(axis=1)))

    def without_cases(self, case_ids: Iterable[str]) -> CaseArrays:
        """All but the cases ``case_ids``."""
        return self.subset(np.flatnonzero(~np.isin(np.array(self.case_ids), list(case_ids))))


def generated_case_arrays(
    world: World, n: int, seed: int, *, shop: str = "synthetic shop"
) -> CaseArrays:
    """``n`` cases of the generated ``world`` (:meth:`~flakelab.cases.generator.World.cases`,
    reproducible from ``seed``) as arrays in its library's toner order, effect toners
    marked."""
    cases = [c for batch in world.cases(n, seed, shop=shop) for c in batch]
    return case_arrays(cases, world.library.names, world.library.effect)


def case_arrays(
    cases: Iterable[Case], toners: Sequence[str], effect: Sequence[bool] | None = None
) -> CaseArrays:
    """Stack cases of one geometry set into training arrays (:func:`~flakelab.cases.case.
    cases_at` brings cases read by several instruments to one set); the arrays' instrument is
    the one whose set it is, else the first case's."""
    index = {name: i for i, name in enumerate(toners)}
    xs, Rs, texs, ids, shops, tins, by_colour = [], [], [], [], [], [], []
    geometries = instrument = None
    for case in cases:
        if geometries is None:
            geometries = case.geometry_names
            instrument = instrument_of(geometries, case.instrument) or case.instrument
        elif case.geometry_names != geometries:
            raise ModelError(
                f"case {case.case_id!r}: geometries {case.geometry_names} differ "
                f"from the first case's {geometries}; train one geometry set at a time"
            )
        x = np.zeros(len(toners))
        for name, amount in case.recipe.items():
            if name not in index:
                raise ModelError(
                    f"case {case.case_id!r}: recipe: toner {name!r} is not in the library"
                    + did_you_mean(name, index)
                )
            x[index[name]] = amount
        strength, shade = np.ones(len(toners)), np.zeros(len(toners))
        for name, tin in case.tins.items():
            strength[index[name]], shade[index[name]] = tin.strength, tin.shade_nm
        tins.append((strength, shade))
        xs.append(x)
        Rs.append(case.sprayout)
        by_colour.append(case.sprayout_recovered)
        texs.append([case.sprayout_texture.get(k, np.nan) for k in TEXTURE_READINGS])
        ids.append(case.case_id)
        shops.append(case.shop)
    if not xs:
        raise ModelError("cases: expected at least one case, got none")
    return CaseArrays(
        np.array(xs),
        np.array(Rs),
        np.array(texs),
        tuple(ids),
        tuple(shops),
        tuple(toners),
        tuple(geometries),
        str(instrument),
        None if effect is None else np.asarray(effect, float),
        *(np.array(column) for column in zip(*tins, strict=True)),
        np.array(by_colour) if any(by_colour) else None,
    ).recorded_tins_only()


EFFECT_SUPPORT_QUANTILE = 0.001
"""Share of a model's effect-paint cases allowed below its effect-share floor."""


def effect_share_floor(x: NDArray, effect: NDArray | None) -> float:
    """The effect toners' share of a recipe below which the cases ``x[N, T]`` hold (almost) no
    effect paint: their :data:`EFFECT_SUPPORT_QUANTILE` quantile over the cases with any effect
    toner; 0 without such cases. Between a solid and that share the model never saw a case,
    and the matcher keeps its recipes out of there (``MatchSettings.effect_floor``)."""
    if effect is None:
        return 0.0
    share = (x * effect).sum(1) / x.sum(1)
    share = share[share > 0]
    return float(np.quantile(share, EFFECT_SUPPORT_QUANTILE)) if share.size else 0.0


def data_hash(data: CaseArrays) -> str:
    """SHA-256 of the training data (recipes, spectra, texture) — recorded with every model."""
    digest = hashlib.sha256()
    for array in (data.x, data.R, data.texture):
        digest.update(np.ascontiguousarray(array, dtype="<f4").tobytes())
    return digest.hexdigest()


def _new_model(data: CaseArrays, config: TrainingConfig, rows: NDArray) -> ForwardModel:
    torch.manual_seed(config.seed)
    probe = ForwardModel(
        data.toners,
        data.geometries,
        data.instrument,
        torch.nn.Identity(),
        config.hidden,
        np.zeros(1),
        np.ones(1),
        np.zeros(1),
        np.ones(1),
        {},
        data.effect,
        config.log_offset,
    )
    y = _targets_read(probe, data, rows)
    x = probe.features(torch.as_tensor(data.x[rows])).numpy()
    network = build_network(x.shape[1], y.shape[1], config.hidden)
    y_mean, y_std = _moments_of_readings(y)
    return ForwardModel(
        data.toners,
        data.geometries,
        data.instrument,
        network,
        tuple(config.hidden),
        x.mean(0),
        x.std(0) + 1e-3,
        y_mean,
        y_std + 1e-3,
        {"config": asdict(config)},
        data.effect,
        config.log_offset,
    )


def _moments_of_readings(y: NDArray) -> tuple[NDArray, NDArray]:
    """Mean and standard deviation of each output over the cases that read it (NaN: not
    read); 0 and 1 for an output no case reads."""
    read = ~np.isnan(y)
    count = read.sum(0)
    mean = np.where(read, y, 0.0).sum(0) / np.maximum(count, 1)
    var = np.where(read, (y - mean) ** 2, 0.0).sum(0) / np.maximum(count, 1)
    return mean, np.where(count > 0, np.sqrt(var), 1.0)


def fit(
    models: Sequence[ForwardModel],
    data: CaseArrays,
    rows: Sequence[NDArray],
    epochs: int,
    learning_rate: float,
    config: TrainingConfig,
    log: list,
    stages: Sequence[str],
    progress: Callable[[int], None] | None = None,
    validation: Sequence[NDArray] | None = None,
) -> tuple[list[int], list[float]] | None:
    """Adam on the loss of the module notes, cosine decay within the stage, for K models at
    once, model k on the cases ``rows[k]`` (logged as ``stages[k]``).

    With ``validation`` (rows per model), each model is judged after every epoch by its mean
    ΔE00 on those cases (logged as ``validation_de00``) and ends with the weights of its best
    epoch, its starting weights included; returns the epochs each kept model trained and its
    validation ΔE00.

    One :class:`StackedNetwork` carries the K networks. The loss is the sum of the models'
    losses and Adam is elementwise, so each model trains as it would alone; the fold models
    of the protocol share each step's fixed cost instead. Folds differ by at most one case:
    an epoch draws the smallest fold's count from each, leaving out at most one case at
    random."""
    ensembles = [m.members for m in models if m.members > 1]
    if ensembles:
        raise ModelError(
            f"fit: a model is an ensemble of {ensembles[0]} networks; fit its members "
            "(ForwardModel.split_members) side by side"
        )
    sizes = [r.size for r in rows]
    if epochs <= 0 or min(sizes) == 0:
        return None
    if config.colour_weight <= 0 and any(data.known_by_colour[r].any() for r in rows):
        raise ModelError(
            "fit: a spray-out known by its colour alone is learnt by the colour term alone; "
            "expected a colour_weight above 0"
        )
    device = training_device(config.device)
    generator = torch.Generator().manual_seed(config.seed + len(log))
    x = _stack_rows([_standard_inputs(m, data.x[r]) for m, r in zip(models, rows, strict=True)])
    y = _stack_rows([_standard_targets(m, data, r) for m, r in zip(models, rows, strict=True)])
    read = (~torch.isnan(y)).to(y.dtype)  # texture a case's instrument did not read: no error
    x, y, read = x.to(device), torch.nan_to_num(y).to(device), read.to(device)
    colour_loss = (
        _colour_loss(models, [data.R[r] for r in rows], device)
        if config.colour_weight > 0
        else None
    )
    network = StackedNetwork([m.network for m in models]).to(device)
    # one kernel for every parameter's update on a GPU, where launches dominate the step
    fused = device.type == "cuda"
    optimiser = torch.optim.Adam(network.parameters(), lr=learning_rate, fused=fused)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimiser, T_max=epochs)
    per_epoch = min(sizes)
    stack = torch.arange(len(models), device=device)[:, None]
    best = None if validation is None else _BestEpoch(models, data, validation, network)
    batch_losses = _batch_losses_for(device)
    for epoch in range(epochs):
        order = torch.stack([torch.randperm(n, generator=generator)[:per_epoch] for n in sizes])
        order = order.to(device)
        totals = torch.zeros(len(models), device=device)
        for start in range(0, per_epoch, config.batch_size):
            batch = order[:, start : start + config.batch_size]
            optimiser.zero_grad()
            losses = batch_losses(
                network, x, y, read, stack, batch, colour_loss, config.colour_weight
            )
            losses.sum().backward()
            optimiser.step()
            totals += losses.detach() * batch.shape[1]
        schedule.step()
        _check_finite(totals, stages, epoch)
        scores = best.update(epoch + 1) if best else [None] * len(models)
        for stage, total, score in zip(stages, totals.tolist(), scores, strict=True):
            entry = {"stage": stage, "epoch": epoch, "loss": total / per_epoch}
            log.append(entry if score is None else entry | {"validation_de00": score})
        if progress:
            progress(len(models))
    if best:
        best.restore()
    network.copy_into([m.network for m in models])
    return None if best is None else (best.epochs.tolist(), best.scores.tolist())


def _batch_losses(network, x, y, read, stack, batch, colour_loss, colour_weight) -> torch.Tensor:
    """Each of the K models' loss (module notes) on its cases ``batch [K, B]``."""
    output = network(x[stack, batch])
    losses = torch.mean((output - y[stack, batch]) ** 2 * read[stack, batch], dim=(1, 2))
    if colour_loss is not None:
        losses = losses + colour_weight * colour_loss(output, batch)
    return losses


@functools.cache
def _batch_losses_for(device: torch.device) -> Callable[..., torch.Tensor]:
    """:func:`_batch_losses`, compiled for a CUDA GPU: there a step of this small network is
    hundreds of kernels of microseconds each (740 tensor operations a step, counted on the
    CPU at batch 1024), bound by their launches, and compiling fuses the element-wise ones
    (the colour term's, chiefly). On the CPU it runs as written: compiling there cost 55 s on
    two cores and gained nothing measurable, and the CPU's numbers stay those it has always
    given. Compiled for each shape it meets (``dynamic=False``: the full batches and an
    epoch's last, for each stage's cases and networks): with dynamic shapes, torch 2.11's
    compiled backward asserted a stride of the screen's case count on the final training's
    (benchmarks/learning.py on an H100; the class of pytorch/pytorch#104653, too few guards
    on the backward)."""
    if device.type == "cuda" and importlib.util.find_spec("triton") is not None:
        torch._dynamo.config.suppress_errors = True  # no compiler at hand: run it as written
        # a shape per stage and fold (a sequential screen trains its folds one by one)
        limit = torch._dynamo.config.recompile_limit
        torch._dynamo.config.recompile_limit = max(limit, 32)
        return torch.compile(_batch_losses, dynamic=False)
    return _batch_losses


class _BestEpoch:
    """Each of a :class:`StackedNetwork`'s models' weights at its lowest mean ΔE00 on its
    validation rows so far, starting from the weights it had before training."""

    def __init__(self, models, data: CaseArrays, rows: Sequence[NDArray], network) -> None:
        self.models, self.data, self.rows, self.network = models, data, rows, network
        self.weights = [p.detach().clone() for p in network.parameters()]
        self.scores = self.judge()
        self.epochs = np.zeros(len(models), int)

    def judge(self) -> NDArray:
        self.network.copy_into([m.network for m in self.models])
        pairs = zip(self.models, self.rows, strict=True)
        return np.array([_residual_error(m, self.data, r).mean() for m, r in pairs])

    def update(self, epoch: int) -> list[float]:
        scores = self.judge()
        better = scores < self.scores
        mask = torch.as_tensor(better, device=self.weights[0].device)
        with torch.no_grad():
            for kept, weight in zip(self.weights, self.network.parameters(), strict=True):
                kept[mask] = weight[mask]
        self.scores = np.where(better, scores, self.scores)
        self.epochs[better] = epoch
        return scores.tolist()

    def restore(self) -> None:
        with torch.no_grad():
            for kept, weight in zip(self.weights, self.network.parameters(), strict=True):
                weight.copy_(kept)


def _standard_inputs(model: ForwardModel, fractions: NDArray) -> torch.Tensor:
    features = model.features(torch.as_tensor(fractions)).numpy()
    return torch.as_tensor((features - model.x_mean) / model.x_std, dtype=torch.float32)


def _targets_read(model: ForwardModel, data: CaseArrays, rows: NDArray) -> NDArray:
    """The outputs a model learns of the cases at ``rows``; NaN (not learnt) where none was
    read: texture an instrument did not read, and the spectrum of a spray-out known by its
    colour alone, which the colour term learns instead (module notes)."""
    y = model.encode_targets(data.R[rows], data.texture[rows])
    y[data.known_by_colour[rows], : model.spectral_outputs] = np.nan
    return y


def _standard_targets(model: ForwardModel, data: CaseArrays, rows: NDArray) -> torch.Tensor:
    y = _targets_read(model, data, rows)
    return torch.as_tensor((y - model.y_mean) / model.y_std, dtype=torch.float32)


def _stack_rows(arrays: Sequence[torch.Tensor]) -> torch.Tensor:
    """``[K, N_max, ...]``, shorter arrays padded with zeros (never drawn)."""
    return torch.nn.utils.rnn.pad_sequence(list(arrays), batch_first=True)


def _check_finite(losses: torch.Tensor, stages: Sequence[str], epoch: int) -> None:
    """A :class:`ModelError` naming the stage and epoch where a model's loss is not finite:
    its weights are lost, and a model file of them would predict nothing."""
    finite = torch.isfinite(losses).tolist()
    if not all(finite):
        stage = stages[finite.index(False)]
        raise ModelError(
            f"training diverged: {stage}, epoch {epoch + 1}: the loss is not a finite number; "
            "train again with another seed or a lower learning rate"
        )


def _colour_loss(
    models: Sequence[ForwardModel],
    reflectance: Sequence[NDArray],
    device: torch.device | str = "cpu",
) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor]:
    """Per model, the mean squared CIE94 difference between standardised network outputs
    ``[K, B, outputs]`` and the measured ``reflectance[k] [N_k, G, 31]`` at ``rows [K, B]``
    (the measured CIELAB computed once), on ``device``."""
    colour = TorchColour(dtype=torch.float32, device=device)
    measured = _stack_rows(
        [
            colour.lab(torch.as_tensor(np.maximum(R, 0.0), dtype=torch.float32, device=device))
            for R in reflectance
        ]
    )
    spectral = models[0].spectral_outputs

    def standard(name: str) -> torch.Tensor:
        values = [getattr(m, name)[:spectral] for m in models]
        return torch.as_tensor(np.array(values), dtype=torch.float32, device=device)[:, None]

    scale, offset = standard("y_std"), standard("y_mean")
    stack = torch.arange(len(models), device=device)[:, None]
    geometry_bands = reflectance[0].shape[1:]

    def loss(output: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
        # clipped as a prediction is: an output far out in one step overflowed exp, and the
        # NaN it made of the loss the weights (stop 107, a member of the five-angle model)
        R = reflectance_from_log(output[..., :spectral] * scale + offset)
        lab = colour.lab(R.reshape(*output.shape[:2], *geometry_bands))
        return torch.mean(TorchColour.delta_e94_squared(measured[stack, rows], lab), dim=(1, 2))

    return loss


def _residual_error(model: ForwardModel, data: CaseArrays, rows: NDArray) -> NDArray:
    """Mean ΔE00 over geometries of each case's prediction: the colorist's own yardstick
    (log-reflectance residuals over-weight near-black spectra, where noise dominates)."""
    R, _ = model.predict(data.x[rows])
    return delta_E(reflectance_to_Lab(data.R[rows]), reflectance_to_Lab(R)).mean(axis=1)


def flag_outliers(
    errors: NDArray, threshold: float, reference: NDArray | None = None
) -> NDArray[np.bool_]:
    """True where an error is more than ``threshold`` robust s.d. above the median of the
    ``reference`` errors (default: ``errors`` themselves)."""
    reference = errors if reference is None else reference
    median = np.median(reference)
    mad = 1.4826 * np.median(np.abs(reference - median)) + 1e-12
    return (errors - median) / mad > threshold


def outlying_cases(model: ForwardModel, data: CaseArrays, threshold: float) -> NDArray[np.bool_]:
    """The cases of ``data`` (one shop's, for :func:`adapt_model`) whose error by ``model``
    lies more than ``threshold`` robust s.d. above their median (module notes, steps 3 and
    5). Three white panels among 403 of a shop's cases flagged exactly the three. Kept,
    they made a good adaptation (ΔE00 1.04 → 0.70 on 500 fresh cases of the shop) read as
    worse on the held-out cases, where one of them fell (1.82 → 1.83), and go unpromoted;
    left out, the adaptation is that of the shop's own cases, to the bit (stop 66).

    Relative to the shop's own spread, not :data:`~flakelab.match.mixups.SPRAYOUT_MISMATCH`'s
    absolute bound as the habits screen: that bound is taken from the prediction moved by the
    shop's habits, and before adapting a shop's own spray-outs lie from the bare model as far
    as its habits put them (the habits shop's up to ΔE00 4.8)."""
    data = _in_model_order(model, data)
    return flag_outliers(_residual_error(model, data, np.arange(data.x.shape[0])), threshold)


class _Stages:
    """The protocol's stages (each a :func:`fit`) run in turn, each kept in ``checkpoint``
    once done (None: none kept); those it kept already are not run again: the log is the
    one it kept, and the last kept stage's networks are restored
    (:mod:`flakelab.models.checkpoint`)."""

    def __init__(self, checkpoint: TrainingCheckpoint | None, progress) -> None:
        self.checkpoint, self.progress = checkpoint, progress
        self.done = 0
        self.kept = checkpoint.stages if checkpoint else 0
        self.log: list[dict] = list(checkpoint.log) if checkpoint else []
        self.outliers = checkpoint.outliers if checkpoint else None

    def fit(self, models, data, rows, epochs, learning_rate, config, names) -> None:
        self.done += 1
        if self.done <= self.kept:
            if self.done == self.kept:
                self.checkpoint.restore(models)
            if self.progress:
                self.progress(epochs * len(models))
            return
        fit(models, data, rows, epochs, learning_rate, config, self.log, names, self.progress)
        if self.checkpoint:
            self.checkpoint.keep(self.done, self.log, models, self.outliers)

    def train(self, models, data, rows, config, names) -> None:
        """A session: ``epochs`` at the learning rate, then ``finetune_epochs`` at the
        fine-tuning rate."""
        self.fit(models, data, rows, config.epochs, config.learning_rate, config, names)
        self.fit(
            models,
            data,
            rows,
            config.finetune_epochs,
            config.finetune_learning_rate,
            config,
            [f"{name} fine-tune" for name in names],
        )

    def screened(self, judge: Callable[[], NDArray[np.bool_]]) -> NDArray[np.bool_]:
        """The outliers ``judge`` finds, or those kept (a checkpoint past the screen keeps
        the final training's networks, not the screen's)."""
        if self.outliers is None:
            self.outliers = judge()
        return self.outliers


def fold_rows(n: int, config: TrainingConfig) -> tuple[list[NDArray], list[NDArray]]:
    """The protocol's seeded partitions of ``n`` cases and, for each, the rows its fold model
    trains on (the other partitions)."""
    partitions = np.array_split(np.random.default_rng(config.seed).permutation(n), config.folds)
    train_rows = [
        np.concatenate([p for j, p in enumerate(partitions) if j != k]) for k in range(config.folds)
    ]
    return partitions, train_rows


def protocol_epochs(config: TrainingConfig, adapt: bool = False) -> int:
    """Model-epochs the protocol runs (what it reports to ``progress``)."""
    sessions = config.folds - 1 if config.screening == "sequential" else config.folds
    per_session = config.epochs + config.finetune_epochs
    adapting = config.adapt_epochs * config.members if adapt else 0
    return (sessions + config.members) * per_session + adapting


def _screen_sequentially(data, config, partitions, stages: _Stages) -> NDArray[np.bool_]:
    """The paper's screen: one model, a session on each partition but the last in turn; the
    last, unseen, sets the yardstick for every case's error."""
    *sessions, validation = partitions
    model = _new_model(data, config, np.concatenate(sessions))
    for k, rows in enumerate(sessions):
        stages.train([model], data, [rows], config, [f"partition {k + 1}"])

    def judge() -> NDArray[np.bool_]:
        errors = _residual_error(model, data, np.arange(data.x.shape[0]))
        return flag_outliers(errors, config.outlier_threshold, reference=errors[validation])

    return stages.screened(judge)


def _screen_by_cross_validation(
    data, config, partitions, train_rows, stages: _Stages
) -> NDArray[np.bool_]:
    """Every case judged by the fold model that did not train on its partition."""
    folds = [_new_model(data, config, rows) for rows in train_rows]
    stages.train(folds, data, train_rows, config, [f"fold {k + 1}" for k in range(config.folds)])

    def judge() -> NDArray[np.bool_]:
        errors = np.zeros(data.x.shape[0])
        for model, held in zip(folds, partitions, strict=True):
            errors[held] = _residual_error(model, data, held)
        return flag_outliers(errors, config.outlier_threshold)

    return stages.screened(judge)


def _train_final(data, config, clean, stages: _Stages) -> ForwardModel:
    """The final training on the cleaned cases: one model, or ``config.members`` side by side
    from seeds ``seed``, ``seed + 1``, … (member 1 starts as the single model would), averaged
    as an ensemble."""
    members = [
        _new_model(data, replace(config, seed=config.seed + k), clean)
        for k in range(config.members)
    ]
    names = ["final"] if config.members == 1 else [f"final {k + 1}" for k in range(config.members)]
    stages.train(members, data, [clean] * config.members, config, names)
    return ForwardModel.ensemble(members)


def protocol_stages(config: TrainingConfig) -> int:
    """The protocol's stages (a session's training or its fine-tuning, each one
    :func:`fit`): two per screening session, two for the final training."""
    sessions = config.folds - 1 if config.screening == "sequential" else 1
    return 2 * (sessions + 1)


def train_protocol(
    data: CaseArrays,
    config: TrainingConfig = TrainingConfig(),
    *,
    progress: Callable[[int], None] | None = None,
    checkpoint: TrainingCheckpoint | None = None,
) -> tuple[ForwardModel, dict]:
    """The protocol's steps 1–4; returns the final model and a report (outliers, losses,
    timings). Step 5 is :func:`adapt_to_shop` (or :func:`adapt_model`) on the model.
    ``checkpoint``: where each stage is kept once done, and from which a training
    interrupted before goes on (:class:`~flakelab.models.checkpoint.TrainingCheckpoint`)."""
    start = time.perf_counter()
    n = data.x.shape[0]
    if n < config.folds * 2:
        raise ModelError(f"cases: expected at least {config.folds * 2} cases to train, got {n}")
    if config.screening not in SCREENINGS:
        raise ModelError(
            f"screening: expected one of {', '.join(SCREENINGS)}, got {config.screening!r}"
        )
    measured = n - int(data.known_by_colour.sum())
    if measured < config.folds * 2:  # the spectral outputs' standardisation, and their shape
        raise ModelError(
            f"cases: expected at least {config.folds * 2} measured spray-outs to learn spectra "
            f"from, got {measured} (the others known by their colour alone)"
        )
    partitions, train_rows = fold_rows(n, config)
    if checkpoint is not None:
        checkpoint.check_fits(n, protocol_stages(config))
    stages = _Stages(checkpoint, progress)
    if config.screening == "sequential":
        outliers = _screen_sequentially(data, config, partitions, stages)
    else:
        outliers = _screen_by_cross_validation(data, config, partitions, train_rows, stages)
    clean = np.flatnonzero(~outliers)
    model = _train_final(data, config, clean, stages)
    log = stages.log
    model.add_learned([data.case_ids[i] for i in clean])
    report = {
        "cases": n,
        "outliers": int(outliers.sum()),
        "outlier_case_ids": [data.case_ids[i] for i in np.flatnonzero(outliers)],
        "seconds": time.perf_counter() - start,
        "device": str(training_device(config.device)),
        "final_loss": log[-1]["loss"],
        "log": log,
    }
    model.info.update(
        {
            "data_hash": data_hash(data),
            "trained_cases": int(clean.size),
            "outliers_dropped": int(outliers.sum()),
            "toner_cases": dict(zip(data.toners, (data.x[clean] > 0).sum(0).tolist(), strict=True)),
            "effect_share_floor": effect_share_floor(data.x[clean], data.effect),
        }
    )
    if note := too_few_readings(model, int(clean.size)):
        warnings.warn(note, Note, stacklevel=2)
    return model, report


def too_few_readings(model: ForwardModel, cases: int) -> str | None:
    """A note where ``cases`` give fewer readings to learn than ``model``'s network has
    weights: it can then fit every one of them and learn little of any other case. The
    shipped models learned about 120,000 cases each: 450 (five-angle) and 690 (MA-T12)
    readings a weight."""
    weights = sum(p.numel() for p in model.network.parameters()) // model.members
    readings = cases * len(model.y_mean)
    if readings >= weights:
        return None
    return (
        f"{counted(cases, 'case')} give {readings:,} readings to learn, fewer than the network's "
        f"{weights:,} weights ({','.join(map(str, model.hidden))} hidden): it fits these cases "
        "and may learn little of any other (a smaller --hidden, or more cases)"
    )


def adaptation_split(rows: NDArray, config: TrainingConfig) -> tuple[NDArray, NDArray | None]:
    """The cases ``rows`` of a shop that its adaptation learns from, and the share
    ``config.adapt_validation`` of them (seeded) held out to choose its epoch (None at 0)."""
    share = config.adapt_validation
    if not 0 <= share < 1:
        raise ModelError(f"adapt_validation: expected a share in [0, 1), got {share}")
    held = round(share * rows.size)
    if share > 0 and not 1 <= held < rows.size:
        raise ModelError(
            f"adaptation: {counted(rows.size, 'case')}: too few to hold out {share:.0%} of them "
            "to choose the epoch; bring more cases or adapt without validation (0)"
        )
    shuffled = np.random.default_rng([config.seed, rows.size]).permutation(rows)
    return (shuffled[held:], shuffled[:held]) if held else (rows, None)


def held_out_split(data: CaseArrays, holdout: float, seed: int) -> tuple[CaseArrays, CaseArrays]:
    """The cases of ``data`` to learn from and those held out to judge, each held out with
    probability ``holdout`` (seeded); both non-empty."""
    n = data.x.shape[0]
    held = np.random.default_rng(seed).random(n) < holdout
    if held.all() or not held.any():
        raise ModelError(f"{counted(n, 'case')}: too few to hold out {holdout:.0%} of them")
    return data.subset(np.flatnonzero(~held)), data.subset(np.flatnonzero(held))


def adaptation_cases(
    model: ForwardModel, data: CaseArrays, holdout: float, config: TrainingConfig
) -> tuple[CaseArrays, CaseArrays | None, CaseArrays]:
    """The cases of ``data`` to adapt ``model`` on, those that choose the epoch (None: a
    share of the former, :func:`adaptation_split`) and those held out to judge it
    (:func:`held_out_split`). Cases it learned from are adapted on, never held out or
    choosing: its error on them flatters it, and every epoch would judge worse than none."""
    seen = model.learned_from(data.case_ids)
    if not seen.any():
        learn, held_out = held_out_split(data, holdout, config.seed)
        return learn, None, held_out
    if seen.all():
        raise ModelError(
            f"the model learned from all {seen.size} of these cases, so none can judge its "
            "adaptation: adapt a model that has not, or to cases it has not seen"
        )
    unseen, held_out = held_out_split(data.subset(np.flatnonzero(~seen)), holdout, config.seed)
    rows, choosing = adaptation_split(np.arange(unseen.x.shape[0]), config)
    learn = data.subset(np.flatnonzero(seen)).joined(unseen.subset(np.sort(rows)))
    return learn, None if choosing is None else unseen.subset(np.sort(choosing)), held_out


def withhold_for_adaptation(
    data: CaseArrays, shop: str, config: TrainingConfig
) -> tuple[CaseArrays, CaseArrays | None]:
    """``data`` without the share of ``shop``'s cases that will choose the epoch of its
    adaptation (:func:`adaptation_split`), and those cases: withheld from the training too,
    since cases the model learned already judge every epoch of the adaptation worse than
    none, the model as it came."""
    validation = adaptation_split(data.shop_rows(shop), config)[1]
    if validation is None:
        return data, None
    rest = np.setdiff1d(np.arange(data.x.shape[0]), validation)
    return data.subset(rest), data.subset(np.sort(validation))


def adapt(
    model: ForwardModel,
    data: CaseArrays,
    rows: NDArray,
    config: TrainingConfig,
    log: list,
    stage: str = "adapt",
    progress: Callable[[int], None] | None = None,
    *,
    validation: NDArray | None = None,
) -> dict:
    """Protocol step 5 on the cases ``rows`` of one shop, ``model`` changed in place. The
    cases ``validation`` (default: with ``config.adapt_validation`` > 0, that share of
    ``rows``, :func:`adaptation_split`) judge every epoch and the best is kept (module
    notes). Returns what it did."""
    train = rows
    if validation is None:
        train, validation = adaptation_split(rows, config)
    # an ensemble adapts member by member, side by side, each keeping its own best epoch
    K = model.members
    members = [model] if K == 1 else model.split_members()
    kept = fit(
        members,
        data,
        [train] * K,
        config.adapt_epochs,
        config.adapt_learning_rate,
        config,
        log,
        [stage] if K == 1 else [f"{stage} {k + 1}" for k in range(K)],
        progress,
        validation=None if validation is None else [validation] * K,
    )
    if K > 1:
        model.network = ForwardModel.ensemble(members).network
    model.add_learned([data.case_ids[i] for i in train])
    return {
        "cases": int(train.size),
        "validation_cases": 0 if validation is None else int(validation.size),
        "epochs": config.adapt_epochs,
        "kept_epochs": config.adapt_epochs if kept is None else kept[0][0],
        "validation_de00_best": None if kept is None else kept[1][0],
    } | ({} if kept is None or K == 1 else {"member_kept_epochs": kept[0]})


def adapt_model(
    model: ForwardModel,
    data: CaseArrays,
    config: TrainingConfig | None = None,
    *,
    stage: str = "adapt",
    shop: str | None = None,
    validation: CaseArrays | None = None,
    progress: Callable[[int], None] | None = None,
) -> tuple[ForwardModel, dict]:
    """A copy of a trained ``model`` adapted to all of ``data`` (one ``shop``'s cases) by
    :func:`adapt`; ``config`` defaults to the one the model was trained with. ``validation``,
    cases of the shop the model never saw, choose the epoch in place of a share of ``data``'s
    (:func:`withhold_for_adaptation`). Returns it and
    a report (what :func:`adapt` did, the loss log). The copy records, in its
    ``info["adaptation"]``, the ``shop`` and which model it was adapted ``from``: a shop's
    habits read against that model are learned by it (:func:`~flakelab.match.habits.
    learned_by`)."""
    if data.geometries != model.geometries:
        raise ModelError(
            f"cases: geometries {data.geometries} differ from the model's {model.geometries}"
        )
    config = config or recorded_config(model)
    n = data.x.shape[0]
    data = _in_model_order(model, data)
    if validation is not None:
        if validation.x.shape[0] == 0:
            raise ModelError("adaptation: expected validation cases to choose the epoch, got none")
        data = data.joined(_in_model_order(model, validation))
    used = {t for t, column in zip(model.toners, data.x.T, strict=True) if np.any(column)}
    novel = [t for t in model.new_toners if t in used]
    if novel:  # their inputs lie far outside what it learned from: gradients blow up to NaN
        raise ModelError(
            f"cases use toners the model knows from too few cases ({', '.join(novel)}); "
            "leave those cases out of the adaptation, as 'flakelab model adapt' does"
        )
    new = replace(model, network=copy.deepcopy(model.network), info=copy.deepcopy(model.info))
    log: list[dict] = []
    rows, judging = np.arange(n), None if validation is None else np.arange(n, data.x.shape[0])
    report = adapt(new, data, rows, config, log, stage, progress, validation=judging)
    new.info["adaptation"] = report | {
        "stage": stage,
        "data_hash": data_hash(data),
        "shop": shop,
        "from": model.identity,
    }
    return new, report | {"log": log}


def adapt_to_shop(
    model: ForwardModel,
    data: CaseArrays,
    shop: str,
    config: TrainingConfig | None = None,
    *,
    leave_out: Iterable[str] = (),
    validation: CaseArrays | None = None,
    progress: Callable[[int], None] | None = None,
) -> tuple[ForwardModel, dict]:
    """Protocol step 5 after :func:`train_protocol`: :func:`adapt_model` on ``shop``'s cases
    of the ``data`` the model was trained on, but for those its screen dropped (``leave_out``,
    case ids) and those with a toner it knows from too few cases (left to the physics scaling,
    as in ``flakelab model adapt``), the epoch chosen on the ``validation`` cases withheld
    from its training (:func:`withhold_for_adaptation`; those screened as
    :func:`outlying_cases` left out). The report says how many cases were left out."""
    config = config or recorded_config(model)
    cases = data.of_shop(shop).without_cases(leave_out)
    usable = cases.without_toners(model.new_toners)
    if usable.x.shape[0] == 0:
        raise ModelError(
            f"adaptation: no cases from shop {shop!r} to adapt to"
            + (f" ({cases.x.shape[0]} use a toner it knows from too few)" if cases.case_ids else "")
        )
    screened = []
    if validation is not None:
        validation = validation.without_toners(model.new_toners)
        outlying = outlying_cases(model, validation, config.outlier_threshold)
        screened = [validation.case_ids[i] for i in np.flatnonzero(outlying)]
        validation = validation.subset(np.flatnonzero(~outlying))
    new, report = adapt_model(
        model,
        usable,
        config,
        stage=f"adapt {shop}",
        shop=shop,
        validation=validation,
        progress=progress,
    )
    left_out = {"left_out_new_toners": cases.x.shape[0] - usable.x.shape[0]}
    return new, report | left_out | {"validation_outlier_case_ids": screened}


def recorded_config(model: ForwardModel) -> TrainingConfig:
    """The :class:`TrainingConfig` a model was trained with (defaults where it recorded none)."""
    # the device it trained on is this machine's choice, not the model's
    names = {f.name for f in fields(TrainingConfig)} - {"device"}
    recorded = {k: v for k, v in model.info.get("config", {}).items() if k in names}
    return replace(TrainingConfig(**recorded), hidden=tuple(model.hidden))


def unseen_by(data: CaseArrays, *models: ForwardModel) -> CaseArrays:
    """The cases of ``data`` none of ``models`` learned from (:meth:`ForwardModel.learned_from`):
    a model retrained on a grown database is judged against the current one on cases held out
    from it, which the current one may have learned."""
    seen = np.zeros(len(data.case_ids), dtype=bool)
    for model in models:
        seen |= model.learned_from(data.case_ids)
    return data.subset(np.flatnonzero(~seen))


@dataclass(frozen=True)
class PredictionErrors:
    """A model's predictions of cases against their measured spray-outs
    (:func:`prediction_errors`): L*a*b* ``[N, G, 3]`` both ways, ΔE00 ``[N, G]``, texture
    readings ``[N, 8]`` (measured: NaN where a case read none), and the prediction's time."""

    geometries: tuple[str, ...]
    measured_lab: NDArray
    predicted_lab: NDArray
    de00: NDArray
    texture: NDArray
    measured_texture: NDArray
    seconds: float


def prediction_errors(
    model: ForwardModel, data: CaseArrays, predict=None, lab_offset=None, *, poured=None
) -> PredictionErrors:
    """The model's predictions of ``data``'s recipes against their spray-outs, at the model's
    geometries. ``predict(x) → (R, texture)`` replaces the model's own prediction (the
    matcher's hybrid forward, for toners new to the model); ``lab_offset(x, R) → [N, G, 3]``
    is added to the predicted L*a*b* (a shop's habits). ``poured(x, strength, shade) → (R,
    texture)`` predicts recipes poured from the tins the cases record (the matcher's
    :class:`~flakelab.match.lots.WithLots`), where they record any."""
    if data.geometries != model.geometries:
        missing = sorted(set(model.geometries) - set(data.geometries))
        if missing:
            raise ModelError(f"cases lack the model's geometries {missing}")
        order = [data.geometries.index(g) for g in model.geometries]
        data = replace(data, R=data.R[:, order], geometries=model.geometries)
    data = _in_model_order(model, data)
    x = data.x
    start = time.perf_counter()
    if poured is not None and data.strength is not None:
        R, texture = poured(x, data.strength, data.shade)
    else:
        R, texture = (predict or model.predict)(x)
    seconds = time.perf_counter() - start
    predicted = reflectance_to_Lab(R) + (0.0 if lab_offset is None else lab_offset(x, R))
    measured = reflectance_to_Lab(data.R)
    return PredictionErrors(
        tuple(model.geometries), measured, predicted, delta_E(measured, predicted),
        np.asarray(texture), data.texture, seconds,
    )  # fmt: skip


def error_summary(
    errors: PredictionErrors, families=None, *, leave_out_above: float | None = None
) -> dict:
    """ΔE00 over cases × geometries and per geometry; mean absolute texture error.
    ``families[N]`` (:meth:`~flakelab.library.toners.Library.paint_families`) adds the figures
    per paint family. With ``leave_out_above``, the cases whose worst ΔE00 over their
    geometries lies above it (``above``: ``[row, ΔE00]``) and the figures without them
    (``without_above``; None where none or all lie above)."""
    de = errors.de00
    report = {
        "cases": int(de.shape[0]),
        **_de00_summary(de),
        "per_geometry": {g: _de00_summary(de[:, i]) for i, g in enumerate(errors.geometries)},
        "texture_mae": _texture_mae(errors.texture, errors.measured_texture),
        "predict_seconds": errors.seconds,
    }
    if leave_out_above is not None:
        worst = de.max(axis=1)
        above = worst > leave_out_above
        report["above"] = [[int(i), float(worst[i])] for i in np.flatnonzero(above)]
        report["without_above"] = None
        if above.any() and not above.all():
            report["without_above"] = {"cases": int((~above).sum()), **_de00_summary(de[~above])}
    if families is not None:
        families = np.asarray(families)
        report["per_family"] = {
            family: {
                "cases": int(np.sum(families == family)),
                **_de00_summary(de[families == family]),
            }
            for family in np.unique(families).tolist()
        }
    return report


def evaluate_model(
    model: ForwardModel,
    data: CaseArrays,
    predict=None,
    lab_offset=None,
    families=None,
    *,
    leave_out_above: float | None = None,
    poured=None,
) -> dict:
    """:func:`error_summary` of the model's :func:`prediction_errors` on ``data``."""
    errors = prediction_errors(model, data, predict, lab_offset, poured=poured)
    return error_summary(errors, families, leave_out_above=leave_out_above)


def _texture_mae(predicted: NDArray, measured: NDArray) -> dict[str, float | None]:
    """Mean absolute error of each texture reading over the cases that read it (None: no
    case did)."""
    read = ~np.isnan(measured)
    error = np.where(read, np.abs(predicted - np.nan_to_num(measured)), 0.0).sum(0)
    return {
        name: round(float(total / n), 4) if n else None
        for name, total, n in zip(TEXTURE_READINGS, error, read.sum(0), strict=True)
    }


def _de00_summary(de: NDArray) -> dict[str, float]:
    """Mean, 95th percentile and largest of the ΔE00 values ``de`` (any shape)."""
    return {
        "de00_mean": float(de.mean()),
        "de00_p95": float(np.percentile(de, 95)),
        "de00_max": float(de.max()),
    }


def _in_model_order(model: ForwardModel, data: CaseArrays) -> CaseArrays:
    """``data`` with its recipes (and tins) over ``model``'s toners, in its order."""
    if data.toners == tuple(model.toners):
        return data
    strength, shade = data.tins()
    tins = data.strength is not None
    return replace(
        data,
        x=_align_toners(model, data),
        toners=model.toners,
        strength=_align_toners(model, data, strength, fill=1.0) if tins else None,
        shade=_align_toners(model, data, shade) if tins else None,
    )


def _align_toners(
    model: ForwardModel, data: CaseArrays, values: NDArray | None = None, fill: float = 0.0
) -> NDArray:
    """``values[N, T]`` (the recipes by default) over ``model``'s toners, ``fill`` where the
    cases have none of a toner; a toner the cases use that the model lacks is refused."""
    index = {name: i for i, name in enumerate(model.toners)}
    values = data.x if values is None else values
    x = np.full((data.x.shape[0], len(model.toners)), fill)
    for j, name in enumerate(data.toners):
        used = data.x[:, j] > 0
        if name not in index:
            if np.any(used):
                raise ModelError(f"cases use toner {name!r}, unknown to the model")
            continue
        x[:, index[name]] = values[:, j]
    return x
