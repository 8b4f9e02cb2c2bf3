"""The learned forward model (DESIGN.md §5): recipe → reflectance at every geometry + texture.

Inputs are mass fractions over the model's toner list (a recipe in any unit is normalised
first); outputs are log reflectance factors at each geometry and band, then the texture
readings. Inputs and outputs are standardised with the training data's statistics, stored
with the weights. Log reflectance makes the loss relative, as colour differences are: a
1 % error costs the same on a dark flop angle as near specular.
"""

from __future__ import annotations

import copy
import hashlib
import io
import json
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import torch
from numpy.typing import ArrayLike, NDArray
from torch import nn

from flakelab.core.documents import MODEL_FORMAT
from flakelab.core.geometry import Geometry
from flakelab.core.measurement import TEXTURE_READINGS
from flakelab.core.spectra import WAVELENGTHS
from flakelab.core.units import check_mass_fractions, is_number
from flakelab.errors import ModelError, shown
from flakelab.models.files import not_a_model_file, stored_meta

__all__ = [
    "FoldedNetwork",
    "ForwardModel",
    "StackedNetwork",
    "build_network",
    "case_fingerprints",
    "LOG_FLOOR",
    "LOG_OFFSET_MAX",
    "MIN_CASES",
    "ModelError",
    "reflectance_from_log",
]

MIN_CASES = 20
"""A toner with fewer training cases than this is new to a learned model: the matcher has
physics scale it (:func:`flakelab.match.models.forward_for`)."""
EFFECT_OFFSET = 0.05
"""Added to the effect-pigment fraction in the ratio features (solids have none)."""
FEATURE_BLOCKS = 2
"""Input blocks of T features each without log features: fractions, per unit effect."""
LOG_OFFSET_MAX = 0.5
"""The largest offset of the log features (:attr:`ForwardModel.log_offset`); beyond it they
are nearly linear in the fractions, which the network has already."""
MAX_HIDDEN = 4096
"""The widest hidden layer a model file may give: forty times the default, far wider than a
forward model of a few dozen toners needs; a corrupt width would allocate its weights."""
MAX_MEMBERS = 64
"""The most networks a model file's ensemble may have (the shipped ones have four)."""
LOG_FLOOR = 1e-3
"""Reflectance factors are clipped here before the log (noise on black can go negative)."""
LOG_CEILING = float(np.log(6.0))
"""Predicted log reflectance factors are capped here: a bright aluminium reads about 3 near
specular; an MLP far outside its data must not extrapolate to absurd values."""


def reflectance_from_log(log_R: torch.Tensor) -> torch.Tensor:
    """Reflectance factors from predicted log reflectance, clipped to what paint can read:
    far below :data:`LOG_FLOOR` (black) and no higher than :data:`LOG_CEILING`."""
    return torch.exp(torch.clamp(log_R, float(np.log(LOG_FLOOR)) - 3, LOG_CEILING))


def _field_error(
    source: str, document: dict, field: str, expected: str, prefix: str = ""
) -> ModelError:
    """A model file's ``field`` (of its description, or of its ``info``: ``prefix``) named
    with what it should be and what it is."""
    given = shown(document[field]) if field in document else "nothing"
    return ModelError(f"{source}: {prefix}{field}: expected {expected}, got {given}")


def _check_meta(meta: dict, source: str) -> None:
    """A model file's description: every field of the type the model needs, named when not
    (a file edited by hand, or cut short)."""

    def wrong(field: str, expected: str) -> ModelError:
        return _field_error(source, meta, field, expected)

    def texts(value: object) -> bool:
        return (
            isinstance(value, list)
            and bool(value)
            and all(isinstance(v, str) and v.strip() for v in value)
        )

    if not texts(meta.get("toners")) or len(set(meta["toners"])) < len(meta["toners"]):
        raise wrong("toners", "a list of distinct toner names")
    if not texts(meta.get("geometries")):
        raise wrong("geometries", "a list of geometry names")
    for name in meta["geometries"]:
        try:
            Geometry.parse(name)
        except ValueError as error:
            raise ModelError(f"{source}: geometries: {error}") from None
    if not isinstance(meta.get("instrument"), str):
        raise wrong("instrument", "a text")
    hidden = meta.get("hidden")
    if not isinstance(hidden, list) or not all(
        isinstance(h, int) and not isinstance(h, bool) and 0 < h <= MAX_HIDDEN for h in hidden
    ):
        raise wrong("hidden", f"a list of layer widths from 1 to {MAX_HIDDEN}")
    if meta.get("texture") != list(TEXTURE_READINGS):
        raise wrong("texture", f"the readings {', '.join(TEXTURE_READINGS)}")
    if not isinstance(meta.get("info"), dict):
        raise wrong("info", "an object")
    _check_info(meta["info"], meta["toners"], source)
    effect = meta.get("effect")
    if (
        not isinstance(effect, list)
        or len(effect) != len(meta["toners"])
        or any(e not in (0, 1) or isinstance(e, bool) for e in effect)
    ):
        raise wrong("effect", f"{len(meta['toners'])} flags of 0 or 1, one a toner")
    members = meta.get("members", 1)
    if not isinstance(members, int) or isinstance(members, bool) or not 0 < members <= MAX_MEMBERS:
        raise wrong("members", f"a whole number from 1 to {MAX_MEMBERS}")
    log_offset = meta.get("log_offset", 0.0)
    if not is_number(log_offset) or not 0 <= log_offset <= LOG_OFFSET_MAX:
        raise wrong("log_offset", f"a number in [0, {LOG_OFFSET_MAX}]")


def _check_info(info: dict, toners: list[str], source: str) -> None:
    """The parts of a model file's ``info`` that matching and the model card read."""

    def wrong(field: str, expected: str) -> ModelError:
        return _field_error(source, info, field, expected, "info.")

    cases = info.get("toner_cases", {})
    if not isinstance(cases, dict) or not all(
        t in toners and isinstance(n, int) and not isinstance(n, bool) and n >= 0
        for t, n in cases.items()
    ):
        raise wrong("toner_cases", "the model's toners, each with a whole number of cases")
    novel = info.get("novel_toners", [])
    if not isinstance(novel, list) or not all(t in toners for t in novel):
        raise wrong("novel_toners", "a list of the model's toners")
    for key in ("name", "data_hash"):
        if not isinstance(info.get(key, ""), str):
            raise wrong(key, "a text")
    floor = info.get("effect_share_floor", 0.0)
    if not is_number(floor) or not 0 <= floor < 1:
        raise wrong("effect_share_floor", "a share from 0 to 1")
    for key in ("config", "adaptation"):
        if not isinstance(info.get(key) or {}, dict):
            raise wrong(key, "an object")


def _checked_norm(norm: object, inputs: int, outputs: int, source: str) -> dict[str, NDArray]:
    """A model file's standardisation: means and standard deviations of its inputs and
    outputs, finite, of the network's sizes, the deviations positive."""
    sizes = {"x_mean": inputs, "x_std": inputs, "y_mean": outputs, "y_std": outputs}
    if not isinstance(norm, dict) or set(norm) != set(sizes):
        raise ModelError(f"{source}: norm: expected {', '.join(sizes)}")
    checked = {}
    for key, size in sizes.items():
        value = norm[key]
        if not isinstance(value, torch.Tensor) or value.shape != (size,):
            shape = tuple(value.shape) if isinstance(value, torch.Tensor) else type(value).__name__
            raise ModelError(f"{source}: norm {key}: expected {size} numbers, got {shape}")
        array = value.numpy().astype(float)
        if not np.all(np.isfinite(array)) or (key.endswith("std") and np.any(array <= 0)):
            what = "positive finite" if key.endswith("std") else "finite"
            raise ModelError(f"{source}: norm {key}: expected {what} numbers")
        checked[key] = array
    return checked


def case_fingerprints(case_ids: Iterable[str]) -> NDArray[np.int64]:
    """64-bit BLAKE2b digests of case ids: a model records the cases it learned from by these
    (8 bytes a case, where ids run to 36 characters), and two ids share one about once in
    10^19 pairs."""
    digests = (hashlib.blake2b(str(c).encode(), digest_size=8).digest() for c in case_ids)
    return np.frombuffer(b"".join(digests), dtype="<i8").astype(np.int64)


def _checked_learned(learned: object, source: str) -> NDArray | None:
    """A model file's record of the cases it learned from: sorted distinct 64-bit integers."""
    if learned is None:
        return None
    if not isinstance(learned, torch.Tensor) or learned.dtype != torch.int64 or learned.dim() != 1:
        raise ModelError(f"{source}: learned: expected one row of 64-bit case fingerprints")
    array = learned.numpy().copy()
    if np.any(np.diff(array) <= 0):
        raise ModelError(f"{source}: learned: expected the case fingerprints sorted, distinct")
    return array


def build_network(inputs: int, outputs: int, hidden: Sequence[int] = (100, 100, 100)) -> nn.Module:
    """MLP with SiLU activations (smooth, so matching gets useful gradients)."""
    layers: list[nn.Module] = []
    width = inputs
    for size in hidden:
        layers += [nn.Linear(width, size), nn.SiLU()]
        width = size
    layers.append(nn.Linear(width, outputs))
    return nn.Sequential(*layers)


class StackedNetwork(nn.Module):
    """K networks of :func:`build_network`'s shape evaluated as one: ``x [K, B, in] →
    [K, B, out]`` with batched matrix products. Training the protocol's fold models together
    shares each step's fixed cost, which dominates small batches on a two-core machine."""

    def __init__(self, networks: Sequence[nn.Module]) -> None:
        super().__init__()
        layers = [[m for m in net if isinstance(m, nn.Linear)] for net in networks]
        self.weights = nn.ParameterList(
            nn.Parameter(torch.stack([net[i].weight.detach().T for net in layers]).contiguous())
            for i in range(len(layers[0]))
        )
        self.biases = nn.ParameterList(
            nn.Parameter(torch.stack([net[i].bias.detach()[None] for net in layers]).contiguous())
            for i in range(len(layers[0]))
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        last = len(self.weights) - 1
        for i, (weight, bias) in enumerate(zip(self.weights, self.biases, strict=True)):
            x = torch.baddbmm(bias, x, weight)
            if i < last:
                x = nn.functional.silu(x)
        return x

    @property
    def members(self) -> int:
        return self.weights[0].shape[0]

    def copy_into(self, networks: Sequence[nn.Module]) -> None:
        """Write the trained weights back into the K separate networks."""
        with torch.no_grad():
            for k, net in enumerate(networks):
                linears = [m for m in net if isinstance(m, nn.Linear)]
                for linear, weight, bias in zip(linears, self.weights, self.biases, strict=True):
                    linear.weight.copy_(weight[k].T)
                    linear.bias.copy_(bias[k, 0])


@dataclass(frozen=True)
class FoldedNetwork:
    """A model's prediction in as few operations as it takes, for inference and matching.

    The input standardisation is folded into the first layer's weights, and the output
    standardisation and the members' mean into one output layer: that layer is linear, so
    the mean of K members' outputs is one product of their last hidden states side by side.
    Equal to the mean of :meth:`ForwardModel.member_outputs` but for float32 rounding; it
    spares the ``[K, N, outputs]`` intermediate and three passes over it, most of an
    ensemble's time once the outputs outnumber the hidden units (MA-T12: 380 against 100)."""

    features: Callable[[torch.Tensor], torch.Tensor]
    layers: tuple[tuple[torch.Tensor, torch.Tensor], ...]
    """The layers before the output layer (each followed by SiLU): weights ``[K, in, out]``
    and biases ``[K, 1, out]``, the first with the input standardisation folded in."""
    head_weight: torch.Tensor
    """``[K × last hidden, outputs]``: the members' output layers stacked, scaled by y_std/K."""
    head_bias: torch.Tensor

    def __call__(self, fractions: torch.Tensor) -> torch.Tensor:
        """Fractions ``[N, T]`` → outputs (log R, texture), de-standardised."""
        x = self.features(fractions)
        members = self.layers[0][0].shape[0]
        h = x.expand(members, *x.shape)
        inplace = not torch.is_grad_enabled()  # no graph to keep: reuse each fresh product
        for weight, bias in self.layers:
            h = nn.functional.silu(torch.baddbmm(bias, h, weight), inplace=inplace)
        side_by_side = h.transpose(0, 1).reshape(x.shape[0], -1)
        return torch.addmm(self.head_bias, side_by_side, self.head_weight)


@dataclass
class ForwardModel:
    """A trained network with everything needed to use it.

    The network is one MLP or, for an *ensemble*, a :class:`StackedNetwork` of K members
    trained on the same cases from different draws; the ensemble predicts the members' mean
    log reflectance, and their disagreement (:meth:`member_outputs`) says where the cases
    taught the model too little to trust it."""

    toners: tuple[str, ...]
    geometries: tuple[str, ...]
    instrument: str
    network: nn.Module
    hidden: tuple[int, ...]
    x_mean: NDArray
    x_std: NDArray
    y_mean: NDArray
    y_std: NDArray
    info: dict
    effect: NDArray | None = None
    log_offset: float = 0.0
    learned: NDArray | None = None
    """:func:`case_fingerprints` of the cases it learned from, sorted; None where its trainer
    recorded none (the shipped models: generated cases no shop holds)."""
    _constants: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    @property
    def new_toners(self) -> tuple[str, ...]:
        """The toners it learned from fewer than ``MIN_CASES`` cases, and those its trainer
        kept out of its cases on purpose (``info.novel_toners``, the shipped models'): the
        matcher's physics scaling stands in for them, and adaptation leaves them out."""
        counts = self.info.get("toner_cases", {})
        declared = set(self.info.get("novel_toners", ()))
        return tuple(
            n for n in self.toners if n in declared or counts.get(n, MIN_CASES) < MIN_CASES
        )

    def learned_from(self, case_ids: Sequence[str]) -> NDArray[np.bool_]:
        """Which of the cases ``case_ids`` it learned from (trained or adapted on): its error
        on them flatters it, so they neither judge it nor choose an adaptation's epoch."""
        if self.learned is None:
            return np.zeros(len(case_ids), dtype=bool)
        return np.isin(case_fingerprints(case_ids), self.learned)

    def add_learned(self, case_ids: Sequence[str]) -> None:
        """Record that it learned from the cases ``case_ids`` too."""
        known = np.empty(0, np.int64) if self.learned is None else self.learned
        self.learned = np.union1d(known, case_fingerprints(case_ids))

    @property
    def members(self) -> int:
        """How many networks the model averages (1: a single MLP)."""
        return self.network.members if isinstance(self.network, StackedNetwork) else 1

    @classmethod
    def ensemble(cls, models: Sequence[ForwardModel]) -> ForwardModel:
        """One model averaging ``models``: networks of one shape trained with the same
        standardisation (the same cases); the first one's record is kept."""
        first = models[0]
        for other in models[1:]:
            if other.hidden != first.hidden or other.toners != first.toners:
                raise ModelError("ensemble: members differ in shape or toners")
            for name in ("x_mean", "x_std", "y_mean", "y_std"):
                if not np.array_equal(getattr(other, name), getattr(first, name)):
                    raise ModelError(f"ensemble: members differ in standardisation ({name})")
        if len(models) == 1:
            return first
        return replace(first, network=StackedNetwork([m.network for m in models]))

    def split_members(self) -> list[ForwardModel]:
        """The members as single models (copies), sharing this model's record."""
        if self.members == 1:
            return [replace(self, network=copy.deepcopy(self.network))]
        networks = [
            build_network(self.x_mean.size, self.y_mean.size, self.hidden)
            for _ in range(self.members)
        ]
        self.network.copy_into(networks)
        return [replace(self, network=net) for net in networks]

    @property
    def spectral_outputs(self) -> int:
        return len(self.geometries) * WAVELENGTHS.size

    # -- encoding ------------------------------------------------------------------------
    def encode_targets(self, reflectance: ArrayLike, texture: ArrayLike) -> NDArray:
        R = np.log(np.maximum(np.asarray(reflectance, dtype=float), LOG_FLOOR))
        return np.concatenate([R.reshape(R.shape[0], -1), np.asarray(texture, float)], axis=1)

    def fractions(self, recipes: Sequence[Mapping[str, float]]) -> NDArray:
        """Recipes ``{toner: amount}`` (any unit) → normalised fractions ``[N, T]``."""
        x = np.zeros((len(recipes), len(self.toners)))
        index = {name: i for i, name in enumerate(self.toners)}
        for row, recipe in enumerate(recipes):
            for name, amount in recipe.items():
                if name not in index:
                    raise ModelError(
                        f"recipe: toner {name!r} is unknown to model "
                        f"{self.info.get('name', '?')} ({len(self.toners)} toners)"
                    )
                x[row, index[name]] = amount
        total = x.sum(axis=1, keepdims=True)
        if np.any(total <= 0):
            raise ModelError("recipe: amounts sum to zero")
        return x / total

    # -- prediction ----------------------------------------------------------------------
    def features(self, fractions: torch.Tensor) -> torch.Tensor:
        """Fractions plus each toner's amount per unit effect pigment: in a metallic the dye
        acts through κ/σ_f (DESIGN.md §3), a ratio an MLP would otherwise have to learn. With
        a ``log_offset`` also log(fraction + offset): a strong pigment changes the colour as
        much from 0.3 % to 1 % as from 3 % to 10 % (Kubelka–Munk's K/S ratios), which fractions
        alone put a hundredth of the input's range apart."""
        mask = self._constant("effect", fractions.dtype)
        effect = (fractions * mask).sum(dim=1, keepdim=True)
        blocks = [fractions, fractions / (effect + EFFECT_OFFSET)]
        if self.log_offset > 0:
            blocks.append(torch.log(fractions + self.log_offset))
        return torch.cat(blocks, dim=1)

    def effect_mask(self) -> NDArray:
        return np.zeros(len(self.toners)) if self.effect is None else np.asarray(self.effect, float)

    def folded(self) -> FoldedNetwork:
        """The model's prediction, differentiable: fractions ``[N, T]`` → outputs (log R,
        texture), de-standardised, an ensemble's members averaged. Folded from the weights as
        they are now (and differentiable with respect to them): fold again after training; a
        caller evaluating one model many times keeps the folded network."""
        dtype = torch.float32
        (first_w, first_b), *inner, (last_w, last_b) = self._layers()
        x_mean, x_std = self._constant("x_mean", dtype), self._constant("x_std", dtype)
        y_mean, y_std = self._constant("y_mean", dtype), self._constant("y_std", dtype)
        first = (first_w / x_std[:, None], first_b - ((x_mean / x_std) @ first_w)[:, None])
        members = last_w.shape[0]
        return FoldedNetwork(
            self.features,
            (first, *inner),
            (last_w * (y_std / members)).reshape(-1, last_w.shape[-1]),
            last_b.mean(dim=0)[0] * y_std + y_mean,
        )

    def _layers(self) -> list[tuple[torch.Tensor, torch.Tensor]]:
        """Each linear layer's weights ``[K, in, out]`` and biases ``[K, 1, out]``."""
        if isinstance(self.network, StackedNetwork):
            return list(zip(self.network.weights, self.network.biases, strict=True))
        return [
            (layer.weight.T[None], layer.bias[None, None])
            for layer in self.network
            if isinstance(layer, nn.Linear)
        ]

    def member_outputs(self, fractions: torch.Tensor) -> torch.Tensor:
        """Each member's outputs ``[K, N, outputs]``, de-standardised (K = 1: one model)."""
        y = self._standard_outputs(fractions)
        y = y if y.dim() == 3 else y[None]
        return y * self._constant("y_std", y.dtype) + self._constant("y_mean", y.dtype)

    def _standard_outputs(self, fractions: torch.Tensor) -> torch.Tensor:
        dtype = fractions.dtype
        x = (self.features(fractions) - self._constant("x_mean", dtype)) / self._constant(
            "x_std", dtype
        )
        if self.members > 1:
            x = x.expand(self.members, *x.shape)
        return self.network(x)

    def _constant(self, name: str, dtype: torch.dtype) -> torch.Tensor:
        """The standardisation statistics and effect mask as tensors, made once per dtype:
        the matcher calls the model hundreds of times per target with small batches, where
        building them each call costs as much as the arithmetic."""
        key = (name, dtype)
        if key not in self._constants:
            value = self.effect_mask() if name == "effect" else getattr(self, name)
            self._constants[key] = torch.as_tensor(np.asarray(value), dtype=dtype)
        return self._constants[key]

    def predict(self, fractions: ArrayLike, batch: int = 2048) -> tuple[NDArray, NDArray]:
        """Reflectance factors ``[N, G, 31]`` and texture readings ``[N, 8]``, in float64.
        Batches of about 2,000 keep an ensemble's hidden states in cache: on this two-core
        machine 16,384 ran at two thirds of the speed (``benchmarks/learning.py``)."""
        x = self._checked_fractions(fractions)
        spectral = self.spectral_outputs
        R = np.empty((x.shape[0], spectral))
        texture = np.empty((x.shape[0], self.y_mean.size - spectral))
        with torch.no_grad():
            forward = self.folded()
            for start in range(0, x.shape[0], batch):
                y = forward(torch.from_numpy(x[start : start + batch]))
                R[start : start + batch] = reflectance_from_log(y[:, :spectral]).numpy()
                texture[start : start + batch] = y[:, spectral:].numpy()
        return R.reshape(x.shape[0], len(self.geometries), WAVELENGTHS.size), texture

    def predict_members(self, fractions: ArrayLike, batch: int = 2048) -> NDArray:
        """Each member's reflectance factors ``[K, N, G, 31]``, in float64."""
        x = self._checked_fractions(fractions)
        spectral = self.spectral_outputs
        with torch.no_grad():
            log_R = torch.cat(
                [
                    self.member_outputs(torch.from_numpy(x[start : start + batch]))[..., :spectral]
                    for start in range(0, x.shape[0], batch)
                ],
                dim=1,
            )
        R = reflectance_from_log(log_R).double().numpy()
        return R.reshape(self.members, x.shape[0], len(self.geometries), WAVELENGTHS.size)

    def _checked_fractions(self, fractions: ArrayLike) -> NDArray:
        x = np.atleast_2d(np.asarray(fractions, dtype=np.float32))
        if x.shape[1] != len(self.toners):
            raise ModelError(f"fractions: expected {len(self.toners)} columns, got {x.shape[1]}")
        check_mass_fractions(x, error=ModelError)
        self.network.eval()
        return x

    @property
    def fingerprint(self) -> str:
        """12 hex digits of the SHA-256 of the weights and normalisation: tells a model from
        its adapted or retrained versions, which keep its name."""
        digest = hashlib.sha256()
        for key, tensor in sorted(self.network.state_dict().items()):
            digest.update(key.encode())
            digest.update(tensor.detach().cpu().numpy().astype("<f4").tobytes())
        for key in ("x_mean", "x_std", "y_mean", "y_std"):
            digest.update(np.asarray(getattr(self, key), "<f4").tobytes())
        return digest.hexdigest()[:12]

    @property
    def adaptation(self) -> dict | None:
        """What its adaptation to a shop's cases recorded (the ``shop``, the model it came
        ``from``, epochs and cases: :func:`~flakelab.models.training.adapt_model`), None where
        it was not adapted."""
        return self.info.get("adaptation")

    @property
    def identity(self) -> str:
        """Which model exactly: its name and :attr:`fingerprint` (what a shop's habits name
        as the model they were read against)."""
        return f"{self.info.get('name', 'model')} {self.fingerprint}"

    # -- storage -------------------------------------------------------------------------
    def to_bytes(self) -> bytes:
        buffer = io.BytesIO()
        meta = {
            "format": MODEL_FORMAT,
            "version": 1,
            "toners": list(self.toners),
            "geometries": list(self.geometries),
            "instrument": self.instrument,
            "hidden": list(self.hidden),
            "members": self.members,
            "texture": list(TEXTURE_READINGS),
            "info": self.info,
            "effect": self.effect_mask().tolist(),
            "log_offset": self.log_offset,
        }
        torch.save(
            {
                "meta": json.dumps(meta),
                "state": self.network.state_dict(),
                "norm": {
                    k: torch.as_tensor(getattr(self, k), dtype=torch.float32)
                    for k in ("x_mean", "x_std", "y_mean", "y_std")
                },
            }
            | ({} if self.learned is None else {"learned": torch.from_numpy(self.learned)}),
            buffer,
        )
        return buffer.getvalue()

    @classmethod
    def from_bytes(cls, data: bytes, source: str = "model") -> ForwardModel:
        try:
            stored = torch.load(io.BytesIO(data), weights_only=True)
        except Exception as error:  # torch raises many types for a bad file
            raise not_a_model_file(source, error) from None
        meta = stored_meta(stored, source)
        _check_meta(meta, source)
        outputs = len(meta["geometries"]) * WAVELENGTHS.size + len(meta["texture"])
        members = meta.get("members", 1)
        log_offset = meta.get("log_offset", 0.0)
        inputs = len(meta["toners"]) * (FEATURE_BLOCKS + (log_offset > 0))
        networks = [build_network(inputs, outputs, meta["hidden"]) for _ in range(members)]
        network = networks[0] if members == 1 else StackedNetwork(networks)
        try:
            network.load_state_dict(stored["state"])
        except (RuntimeError, KeyError, TypeError, AttributeError) as error:
            first = str(error).splitlines()[0]
            raise ModelError(f"{source}: weights do not fit the recorded shape ({first})") from None
        if not all(torch.isfinite(t).all() for t in network.state_dict().values()):
            raise ModelError(f"{source}: weights: expected finite numbers, got NaN or infinity")
        norm = _checked_norm(stored.get("norm"), inputs, outputs, source)
        learned = _checked_learned(stored.get("learned"), source)
        return cls(
            tuple(meta["toners"]),
            tuple(meta["geometries"]),
            meta["instrument"],
            network,
            tuple(meta["hidden"]),
            info=meta["info"],
            effect=np.array(meta["effect"]),
            log_offset=float(log_offset),
            learned=learned,
            **norm,
        )
