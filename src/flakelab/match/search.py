"""Recipe search: from a target measurement to ranked candidate formulations (DESIGN.md §6).

1. **Screen** (all toners at once): several restarts, each starting from one effect base (or
   none, for a solid), optimise softmax amounts against the multi-angle loss plus a
   square-root sparsity penalty. The restarts' best solutions say which effect toners and
   pigments the target needs.
2. **Subsets** (smart pruning, not enumeration of the library): every combination of the
   three most used effect toners (a pearl over an aluminium base takes all three) × every
   combination of up to ``max_pigments`` of the six most used pigments.
3. **Optimise** all subsets at once (one batch through the forward model, autograd, Adam on
   masked softmax logits: amounts stay non-negative and sum to the can), by successive
   halving: a third of the steps on every subset, the rest on the ``refine_keep`` best.
4. **Judge** with the numbers the colorist sees — CIEDE2000 per geometry from
   colour-science, texture differences, the tolerance — plus a small penalty per toner, and
   return the best distinct candidates.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from flakelab.core.colorimetry import reflectance_to_Lab
from flakelab.core.difference import delta_E, delta_LCH
from flakelab.core.measurement import TEXTURE_READINGS
from flakelab.core.tolerance import Tolerance, tolerance_preset
from flakelab.core.torch_colour import TorchColour
from flakelab.errors import FlakelabError

__all__ = ["Candidate", "MatchResult", "MatchSettings", "match", "MatchError"]


IMPORTANCE_FLOOR = 0.02
"""A toner whose removal from the screen's solutions raises the loss (ΔE94 units) by less
than this is not worth a refinement."""


class MatchError(FlakelabError):
    """A target or library the matcher cannot work with."""


@dataclass(frozen=True)
class MatchSettings:
    candidates: int = 5
    max_pigments: int = 4
    screen_steps: int = 120
    refine_steps: int = 150
    refine_keep: int = 24
    novel_threshold: float = 1.5
    top_pigments: int = 6
    top_effects: int = 3
    sparsity: float = 0.4
    toner_penalty: float = 0.05
    texture_weight: float = 0.1
    min_amount: float = 0.002
    seed: int = 0


@dataclass
class Candidate:
    """One recipe with its predicted appearance and its differences to the target."""

    fractions: dict[str, float]
    geometries: tuple[str, ...]
    reflectance: NDArray
    lab: NDArray
    target_lab: NDArray
    de00: NDArray
    dLCH: NDArray
    texture: dict[str, float]
    texture_delta: dict[str, float]
    passes: bool
    failing: list[str]
    model: str
    novel: list[str]
    score: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "recipe": {k: round(v, 6) for k, v in self.fractions.items()},
            "model": self.model,
            "novel_toners": self.novel,
            "passes": self.passes,
            "failing_geometries": self.failing,
            "de00_max": float(self.de00.max()),
            "de00_mean": float(self.de00.mean()),
            "geometries": {
                g: {
                    "L": round(float(self.lab[i, 0]), 3),
                    "a": round(float(self.lab[i, 1]), 3),
                    "b": round(float(self.lab[i, 2]), 3),
                    "dL": round(float(self.dLCH[i, 0]), 3),
                    "dC": round(float(self.dLCH[i, 1]), 3),
                    "dH": round(float(self.dLCH[i, 2]), 3),
                    "dE00": round(float(self.de00[i]), 3),
                }
                for i, g in enumerate(self.geometries)
            },
            "texture_delta": {k: round(v, 3) for k, v in self.texture_delta.items()},
        }


@dataclass
class MatchResult:
    target: str
    geometries: tuple[str, ...]
    candidates: list[Candidate]
    tolerance: str
    seconds: float
    subsets_tried: int
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "target": self.target,
            "geometries": list(self.geometries),
            "tolerance": self.tolerance,
            "seconds": round(self.seconds, 3),
            "subsets_tried": self.subsets_tried,
            "notes": self.notes,
            "candidates": [c.to_dict() for c in self.candidates],
        }


def _masked_softmax(logits: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    return torch.softmax(logits.masked_fill(~mask, -1e4), dim=1)


def _loss(
    forward,
    colour: TorchColour,
    x: torch.Tensor,
    target_lab: torch.Tensor,
    target_texture: torch.Tensor | None,
    settings: MatchSettings,
) -> torch.Tensor:
    R, texture = forward(x)
    de = colour.delta_e94(target_lab[None], colour.lab(R))
    loss = de.mean(dim=1) + 0.5 * de.max(dim=1).values
    if target_texture is not None and texture is not None:
        loss = loss + settings.texture_weight * (texture[:, -2:] - target_texture[-2:]).abs().sum(1)
    return loss


def _optimise(
    forward, colour, logits, mask, target_lab, target_texture, settings, steps, sparsity
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Adam on the logits of every row at once; returns the logits, amounts and losses."""
    logits = logits.clone().requires_grad_(True)
    optimiser = torch.optim.Adam([logits], lr=0.08, fused=True)
    for _ in range(steps):
        optimiser.zero_grad()
        x = _masked_softmax(logits, mask)
        loss = _loss(forward, colour, x, target_lab, target_texture, settings)
        if sparsity:
            loss = loss + sparsity * torch.sqrt(x + 1e-4).sum(1)
        loss.sum().backward()
        optimiser.step()
    with torch.no_grad():
        x = _masked_softmax(logits, mask)
        return logits.detach(), x, _loss(forward, colour, x, target_lab, target_texture, settings)


def _screen(forward, colour, allowed, effect, target_lab, target_texture, settings, generator):
    T = len(forward.toners)
    starts = [i for i in np.flatnonzero(effect & allowed)] + [None, None]
    logits = 0.3 * torch.randn(len(starts), T, generator=generator, dtype=forward.dtype) - 2.0
    for row, i in enumerate(starts):
        if i is not None:
            logits[row, i] = 2.0
    mask = torch.as_tensor(np.tile(allowed, (len(starts), 1)))
    _, x, loss = _optimise(
        forward,
        colour,
        logits,
        mask,
        target_lab,
        target_texture,
        settings,
        settings.screen_steps,
        settings.sparsity,
    )
    return x, loss


def _refine(forward, colour, init, mask, target_lab, target_texture, settings) -> torch.Tensor:
    """Successive halving: a third of ``refine_steps`` on every subset, the rest on the
    ``refine_keep`` best so far (a subset far behind after a third rarely wins; the batch
    shrinks and the search's time with it)."""
    first = settings.refine_steps // 3
    logits, _, loss = _optimise(
        forward, colour, init, mask, target_lab, target_texture, settings, first, 0.0
    )
    keep = torch.argsort(loss)[: settings.refine_keep]
    _, x, _ = _optimise(
        forward,
        colour,
        logits[keep],
        mask[keep],
        target_lab,
        target_texture,
        settings,
        settings.refine_steps - first,
        0.0,
    )
    return x


def _subsets(
    x_screen: NDArray, importance: NDArray, effect: NDArray, settings: MatchSettings
) -> list[tuple[int, ...]]:
    """Toner sets to refine, from the screen's best solutions ``x_screen[S, T]`` and each
    toner's ``importance[T]`` in them (:func:`_importance`)."""
    ranked = [i for i in np.argsort(-importance) if importance[i] > IMPORTANCE_FLOOR]
    effects = [i for i in ranked if effect[i]][: settings.top_effects]
    pigments = [i for i in ranked if not effect[i]][: settings.top_pigments]
    bases: list[tuple[int, ...]] = [()] if x_screen[:, effect].sum(1).min() < 0.05 else []
    for size in range(1, len(effects) + 1):
        bases += list(itertools.combinations(effects, size))
    subsets = []
    for base in bases or [()]:
        for size in range(0 if base else 1, settings.max_pigments + 1):
            subsets += [base + combo for combo in itertools.combinations(pigments, size)]
    # each screen solution's own toners too, so that the screen's best is always reachable
    subsets += [_support(row, effect, settings) for row in x_screen]
    return list(dict.fromkeys(tuple(sorted(s)) for s in subsets if s))


def _importance(forward, colour, x_best, target_lab, target_texture, settings) -> NDArray:
    """How much each toner matters to the screen's best solutions ``x_best[S, T]``: the
    largest rise in loss when it is taken out (the rest renormalised). Amount alone misses
    a tint: 0.2 % of a red pigment can carry a whole colour in a silver metallic, where the
    aluminiums are tens of per cent and interchangeable."""
    S, T = x_best.shape
    rows, toners = np.nonzero(x_best > 1e-4)
    without = x_best[rows].copy()
    without[np.arange(rows.size), toners] = 0.0
    without /= without.sum(axis=1, keepdims=True)
    with torch.no_grad():
        losses = _loss(
            forward,
            colour,
            torch.as_tensor(np.concatenate([x_best, without]), dtype=forward.dtype),
            target_lab,
            target_texture,
            settings,
        ).numpy()
    importance = np.zeros(T)
    np.maximum.at(importance, toners, losses[S:] - losses[rows])
    return importance


def _support(x: NDArray, effect: NDArray, settings: MatchSettings) -> tuple[int, ...]:
    """The toners a screen solution uses (≥ 1 %): at most ``top_effects`` effect toners and
    ``max_pigments`` pigments, the largest amounts."""
    order = [i for i in np.argsort(-x) if x[i] >= 0.01]
    effects = [i for i in order if effect[i]][: settings.top_effects]
    pigments = [i for i in order if not effect[i]][: settings.max_pigments]
    return tuple(sorted(effects) + sorted(pigments))


def _target_spectra(target, forward) -> tuple[NDArray, dict[str, float], str]:
    """Reflectance ``[G, 31]`` of the target at the forward model's geometries."""
    if isinstance(target, np.ndarray):
        return target, {}, "target"
    names = [g.name for g in target.geometries]
    missing = [g for g in forward.geometries if g not in names]
    if missing:
        raise MatchError(
            f"{target.sample}: geometries {', '.join(missing)} missing: the model "
            f"({forward.name}) needs {', '.join(forward.geometries)}"
        )
    if target.wavelengths.size != 31 or target.wavelengths[0] != 400:
        from flakelab.core.spectra import resample

        spectra = resample(target.reflectance, target.wavelengths)
    else:
        spectra = target.reflectance
    return (
        spectra[[names.index(g) for g in forward.geometries]],
        dict(target.texture),
        target.sample,
    )


def match(*args, **kwargs) -> MatchResult:
    """Ranked candidate recipes for a target; see :func:`_match` (run on one thread: the
    batches are small, and a second thread only adds contention)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return _match(*args, **kwargs)
    finally:
        torch.set_num_threads(threads)


def _match(
    target,
    forward,
    effect: NDArray | None = None,
    *,
    tolerance: Tolerance | None = None,
    settings: MatchSettings | None = None,
    allowed: NDArray | None = None,
) -> MatchResult:
    """Ranked candidate recipes for ``target`` (a Measurement or reflectance ``[G, 31]``).

    ``effect[T]`` marks effect toners (aluminium, pearls); ``allowed[T]`` restricts the
    toners the search may use (default: all).
    """
    start = time.perf_counter()
    settings = settings or MatchSettings()
    tolerance = tolerance or tolerance_preset("refinish")
    T = len(forward.toners)
    effect = np.zeros(T, bool) if effect is None else np.asarray(effect, bool)
    allowed = np.ones(T, bool) if allowed is None else np.asarray(allowed, bool)
    if not allowed.any():
        raise MatchError("library: no toners to match with")
    spectra, texture, name = _target_spectra(target, forward)
    colour = TorchColour(dtype=forward.dtype)
    target_lab = colour.lab(torch.as_tensor(spectra))
    target_texture = None
    if texture and all(k in texture for k in TEXTURE_READINGS):
        target_texture = torch.as_tensor(
            [texture[k] for k in TEXTURE_READINGS], dtype=forward.dtype
        )
    generator = torch.Generator().manual_seed(settings.seed)
    # 1. screen: one restart per effect toner, plus solid starts; toners new to the learned
    #    model (physics-scaled, slower) join only when the known ones cannot get close
    novel = np.array([n in forward.novel for n in forward.toners])
    x_screen, screen_loss = _screen(
        forward, colour, allowed & ~novel, effect, target_lab, target_texture, settings, generator
    )
    if novel.any() and float(screen_loss.min()) > settings.novel_threshold:
        x_all, loss_all = _screen(
            forward, colour, allowed, effect, target_lab, target_texture, settings, generator
        )
        x_screen = torch.cat([x_screen, x_all])
        screen_loss = torch.cat([screen_loss, loss_all])
    best = torch.argsort(screen_loss)[:3].numpy()
    x_best = x_screen.numpy()[best].astype(float)
    importance = _importance(forward, colour, x_best, target_lab, target_texture, settings)
    subsets = _subsets(x_best, importance, effect, settings)
    # 2.–3. refine every subset in one batch, then only the most promising
    subset_mask = np.zeros((len(subsets), T), bool)
    for row, subset in enumerate(subsets):
        subset_mask[row, list(subset)] = True
    start_x = x_screen.numpy()[best[0]]
    init = torch.as_tensor(np.log(start_x + 1e-2))[None].repeat(len(subsets), 1)
    x_refined = _refine(
        forward, colour, init, torch.as_tensor(subset_mask), target_lab, target_texture, settings
    )
    x = x_refined.numpy().astype(float)
    x[x < settings.min_amount] = 0.0
    x /= x.sum(axis=1, keepdims=True)
    candidates = _judge(forward, x, spectra, texture, tolerance, settings)
    notes = []
    if candidates and not candidates[0].passes:
        notes.append(
            "no candidate passes the tolerance: best achievable shown; fails at "
            + ", ".join(candidates[0].failing)
        )
    return MatchResult(
        name,
        tuple(forward.geometries),
        candidates,
        tolerance.name,
        time.perf_counter() - start,
        len(subsets),
        notes,
    )


def evaluate_recipes(forward, x: NDArray) -> tuple[NDArray, NDArray | None]:
    with torch.no_grad():
        R, texture = forward(torch.as_tensor(x, dtype=forward.dtype))
    return R.double().numpy(), None if texture is None else texture.double().numpy()


def _judge(forward, x, spectra, texture, tolerance, settings) -> list[Candidate]:
    R, tex = evaluate_recipes(forward, x)
    target_lab = reflectance_to_Lab(spectra)
    lab = reflectance_to_Lab(R)
    de = delta_E(target_lab[None], lab)
    score = de.max(1) + de.mean(1) + settings.toner_penalty * (x > 0).sum(1)
    has_texture = tex is not None and texture and all(k in texture for k in TEXTURE_READINGS)
    if has_texture:
        target_tex = np.array([texture[k] for k in TEXTURE_READINGS])
        score = score + settings.texture_weight * np.abs(tex[:, -2:] - target_tex[-2:]).sum(1)
    chosen, seen = [], set()
    for row in np.argsort(score):
        key = tuple(np.flatnonzero(x[row] > 0))
        if key in seen:
            continue
        seen.add(key)
        chosen.append(row)
        if len(chosen) == settings.candidates:
            break
    out = []
    for row in chosen:
        dlch = delta_LCH(target_lab, lab[row])
        passed = tolerance.passes(forward.geometries, de00=de[row], dLCH=dlch)
        fractions = {
            forward.toners[j]: float(x[row, j]) for j in np.argsort(-x[row]) if x[row, j] > 0
        }
        out.append(
            Candidate(
                fractions=fractions,
                geometries=tuple(forward.geometries),
                reflectance=R[row],
                lab=lab[row],
                target_lab=target_lab,
                de00=de[row],
                dLCH=dlch,
                texture={}
                if tex is None
                else dict(zip(TEXTURE_READINGS, tex[row].tolist(), strict=True)),
                texture_delta={}
                if not has_texture
                else {k: float(tex[row, i] - texture[k]) for i, k in enumerate(TEXTURE_READINGS)},
                passes=bool(np.all(passed)),
                failing=[g for g, ok in zip(forward.geometries, passed, strict=True) if not ok],
                model=forward.name,
                novel=[n for n in fractions if n in forward.novel],
                score=float(score[row]),
            )
        )
    return out
