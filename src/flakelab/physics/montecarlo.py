"""Reference Monte Carlo: photons traced through the basecoat, scored into detectors.

What it traces (DESIGN.md §3, "full ray tracing"): refraction into the coating, flakes met
as a Poisson process (delta tracking with majorant N·πa² per unit path; a tentative hit on a
flake of sampled normal n is real with probability |d·n|), mirror reflection on aluminium
with its complex-index Fresnel reflectance, pearls reflecting or transmitting, pigment
absorption along every path, Henyey–Greenstein scattering (spectral tracking with a
majorant over wavelengths, history-aware: Kutz et al. 2017), a Lambertian primer, Fresnel
reflection and total internal reflection at the top. Every tentative collision and primer
hit also scores the detectors by next-event estimation; exit paths are attenuated by the
expected flake, pigment and scattering extinction along the detector direction.

All 31 bands ride on one path (paths do not depend on wavelength; only weights do), each
photon draws from its own counter-based random stream (seed, photon index), so results do
not depend on the number of threads. Standard errors come from the per-photon scores.

Also recorded, for each detector: the scalar path weight binned by flake-bounce count k and
binder path length L (:class:`PathTable`) — what turns a dye-free run into the fast model
for any transparent dye (:mod:`flakelab.physics.fast`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from flakelab.core.spectra import WAVELENGTHS
from flakelab.physics.layer import (
    Layer,
    interface_directions,
    mean_projected_cosine,
)

__all__ = ["MonteCarloResult", "PathTable", "simulate", "MAX_BOUNCES", "ROUND_PHOTONS"]

MAX_BOUNCES = 63
"""Flake-bounce counts recorded separately in path tables; the last slot holds ≥ 63 (light
trapped between flakes and the coating's top by total internal reflection bounces often)."""
PATH_BINS = 400
"""Binder path-length bins of the path tables (mean length kept per bin; the last one holds
everything longer)."""
MAX_EVENTS = 200_000
"""Events after which a photon is dropped (counted in ``MonteCarloResult.capped``)."""
ROUND_PHOTONS = 1024
"""Photons each chunk traces before the compiled tracer hands back to Python. Compiled code
holds the interpreter, so a Ctrl-C or SIGTERM waited for the whole run (hours at 10⁹
photons); it now stops the run within a round (about 0.25 s for eight chunks of the scaling
experiment's coatings on two cores), and each round reports progress."""


@dataclass(frozen=True)
class PathTable:
    """Dye-free detector weight by flake-bounce count and binder path length.

    ``weight[G, K, B]`` sums of BRDF contributions with the flakes' band-mean reflectance at
    each bounce's own incidence but no dye; ``length[G, K, B]`` the weight-mean path length
    of each bin [µm]; ``reflectance[W]`` the spectral shape of a bounce, R(λ)/mean R
    (aluminium's shape hardly changes with incidence: < 1.5 % from 0° to 60°).
    """

    weight: NDArray[np.float64]
    length: NDArray[np.float64]
    reflectance: NDArray[np.float64]

    @cached_property
    def _collapsed(self) -> tuple[NDArray, NDArray]:
        """Bounce counts folded in once: W[G, B, W] = Σ_k w(k, L)·s(λ)^k, L̄[G, B] (non-empty
        path-length bins only)."""
        k = np.arange(self.weight.shape[1])
        spectral = np.einsum("gkb,kw->gbw", self.weight, self.reflectance[None, :] ** k[:, None])
        bin_weight = self.weight.sum(axis=1)
        mean_length = np.divide(
            (self.weight * self.length).sum(axis=1),
            bin_weight,
            out=np.zeros_like(bin_weight),
            where=bin_weight > 0,
        )
        used = np.flatnonzero(bin_weight.sum(axis=0) > 0)
        return spectral[:, used], mean_length[:, used]

    def brdf(self, absorption: ArrayLike) -> NDArray[np.float64]:
        """f(λ) = Σ_{k,L} w(k,L) · s(λ)^k · exp(−κ(λ)·L) for dye absorption ``[F, W]``.

        Exact for transparent dyes (they change no path, only its weight) up to the averages
        within a 0.5 µm path-length bin; ``[F, G, W]``.
        """
        kappa = np.atleast_2d(np.asarray(absorption, dtype=float))
        spectral, length = self._collapsed
        attenuation = np.exp(-kappa[:, None, None, :] * length[None, :, :, None])
        return np.einsum("gbw,fgbw->fgw", spectral, attenuation)


@dataclass(frozen=True)
class MonteCarloResult:
    """BRDF ``[G, W]`` [1/sr] with its standard error, the body albedo ``[W]`` (light that
    leaves the coating after entering it, per unit incident light) with its standard error,
    the dye-free path table, photon count, dropped (capped) photons and wall time [s]."""

    brdf: NDArray[np.float64]
    stderr: NDArray[np.float64]
    albedo: NDArray[np.float64]
    albedo_stderr: NDArray[np.float64]
    table: PathTable
    photons: int
    capped: int
    seconds: float


@numba.njit(cache=True, inline="always")
def _next(state):
    """splitmix64 step on a one-element uint64 array; returns a float in [0, 1)."""
    state[0] += np.uint64(0x9E3779B97F4A7C15)
    z = state[0]
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return float(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@numba.njit(cache=True)
def _orientation_pdf(theta, sd):
    if theta > np.pi / 2:
        return 0.0
    norm = 2 * np.pi * sd * sd * (1 - np.exp(-((np.pi / 2) ** 2) / (2 * sd * sd)))
    ratio = theta / np.sin(theta) if theta > 1e-8 else 1.0
    return ratio * np.exp(-theta * theta / (2 * sd * sd)) / norm


@numba.njit(cache=True)
def _frame_direction(d0, d1, d2, cos_t, phi):
    """Unit vector at polar angle acos(cos_t), azimuth phi around the axis (d0, d1, d2)."""
    sin_t = np.sqrt(max(0.0, 1 - cos_t * cos_t))
    if abs(d2) < 0.999:
        a0, a1, a2 = -d1, d0, 0.0
    else:
        a0, a1, a2 = 0.0, -d2, d1
    norm = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    a0, a1, a2 = a0 / norm, a1 / norm, a2 / norm
    b0, b1, b2 = d1 * a2 - d2 * a1, d2 * a0 - d0 * a2, d0 * a1 - d1 * a0
    c, s = np.cos(phi) * sin_t, np.sin(phi) * sin_t
    return (
        a0 * c + b0 * s + d0 * cos_t,
        a1 * c + b1 * s + d1 * cos_t,
        a2 * c + b2 * s + d2 * cos_t,
    )


@numba.njit(cache=True)
def _dielectric_reflectance(cos_i, n1, n2):
    sin2_t = (n1 / n2) ** 2 * (1 - cos_i * cos_i)
    if sin2_t >= 1.0:
        return 1.0
    cos_t = np.sqrt(1 - sin2_t)
    rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    rp = (n2 * cos_i - n1 * cos_t) / (n2 * cos_i + n1 * cos_t)
    return 0.5 * (rs * rs + rp * rp)


@numba.njit(cache=True)
def _hg_pdf(cos_t, g):
    return (1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * cos_t) ** 1.5)


@numba.njit(cache=True)
def _trace(first, count, seed, optics, tallies):
    """Photons ``first … first + count``; ``optics`` and ``tallies`` as packed by
    :func:`simulate` (read-only inputs; this chunk's accumulators)."""
    (
        diffuse_in,
        d_in,
        w0,
        det,
        det_factor,
        det_att,
        det_flake_att,
        rates,
        sds,
        refl,
        transmits,
        refl_mean,
        kappa,
        sigma,
        g,
        H,
        primer,
        n,
        path_step,
    ) = optics
    (
        score_sum,
        score_sq,
        albedo_sum,
        albedo_sq,
        table_w,
        table_wl,
        capped,
    ) = tallies
    G, W = det_att.shape
    S = rates.shape[0]
    K, B = table_w.shape[1], table_w.shape[2]
    rate_total = rates.sum()
    sigma_bar = sigma.max()
    ratio = sigma / sigma_bar if sigma_bar > 0 else np.zeros(W)
    primer_mean = primer.mean()
    state = np.zeros(1, dtype=np.uint64)
    w = np.empty(W)
    score = np.empty((G, W))
    rl = np.empty(W)
    for photon in range(first, first + count):
        state[0] = np.uint64(seed) * np.uint64(0xD1B54A32D192ED03) + np.uint64(photon)
        _next(state)
        if diffuse_in:
            cos_t = np.sqrt(_next(state))
            d0, d1, d2 = _frame_direction(0.0, 0.0, -1.0, cos_t, 2 * np.pi * _next(state))
        else:
            d0, d1, d2 = d_in[0], d_in[1], d_in[2]
        for j in range(W):
            w[j] = w0
        score[:, :] = 0.0
        gw, depth, L, k = w0, 0.0, 0.0, 0
        scalar_path = True
        for event in range(MAX_EVENTS):
            if event == MAX_EVENTS - 1:
                capped[0] += 1
                break
            total = rate_total + sigma_bar
            s = -np.log(1.0 - _next(state)) / total if total > 0 else np.inf
            to_boundary = (H - depth) / -d2 if d2 < 0 else depth / d2
            if s >= to_boundary:
                for j in range(W):
                    w[j] *= np.exp(-kappa[j] * to_boundary)
                L += to_boundary
                if d2 < 0:  # primer: Lambertian, scores every detector
                    depth = H
                    for gi in range(G):
                        mu = det[gi, 2]
                        base = mu / np.pi * det_factor[gi]
                        for j in range(W):
                            score[gi, j] += w[j] * primer[j] * base * np.exp(-det_att[gi, j] * H)
                    for j in range(W):
                        w[j] *= primer[j]
                    gw *= primer_mean
                    d0, d1, d2 = _frame_direction(
                        0.0, 0.0, 1.0, np.sqrt(_next(state)), 2 * np.pi * _next(state)
                    )
                else:  # top: internal Fresnel reflection or escape
                    depth = 0.0
                    if _next(state) < _dielectric_reflectance(d2, n, 1.0):
                        d2 = -d2
                    else:
                        for j in range(W):
                            albedo_sum[j] += w[j]
                            albedo_sq[j] += w[j] * w[j]
                        break
            else:
                depth -= s * d2
                L += s
                for j in range(W):
                    w[j] *= np.exp(-kappa[j] * s)
                if _next(state) * total < rate_total:  # tentative flake collision
                    u = _next(state) * rate_total
                    sp = 0
                    while sp < S - 1 and u >= rates[sp]:
                        u -= rates[sp]
                        sp += 1
                    sd = sds[sp]
                    for gi in range(G):
                        h0, h1, h2 = det[gi, 0] - d0, det[gi, 1] - d1, det[gi, 2] - d2
                        hn = np.sqrt(h0 * h0 + h1 * h1 + h2 * h2)
                        h0, h1, h2 = h0 / hn, h1 / hn, h2 / hn
                        if h2 < 0:
                            h0, h1, h2 = -h0, -h1, -h2
                        p = _orientation_pdf(np.arccos(min(1.0, h2)), sd) / 4.0
                        if p <= 0:
                            continue
                        cos_inc = abs(d0 * h0 + d1 * h1 + d2 * h2)
                        a = np.degrees(np.arccos(min(1.0, cos_inc)))
                        ia = min(int(a), 89)
                        fa = a - ia
                        base = p * det_factor[gi]
                        for j in range(W):
                            R = refl[sp, ia, j] * (1 - fa) + refl[sp, ia + 1, j] * fa
                            score[gi, j] += w[j] * R * base * np.exp(-det_att[gi, j] * depth)
                        if scalar_path and not transmits[sp]:
                            mu = det[gi, 2]
                            total_L = L + depth / mu
                            b = min(int(total_L / path_step), B - 1)
                            kk = min(k + 1, K - 1)
                            R = refl_mean[sp, ia] * (1 - fa) + refl_mean[sp, ia + 1] * fa
                            c = gw * R * base * np.exp(-det_flake_att[gi] * depth)
                            table_w[gi, kk, b] += c
                            table_wl[gi, kk, b] += c * total_L
                    # sample the flake's normal; the hit is real with probability |d·n|
                    theta = sd * np.sqrt(
                        -2
                        * np.log(
                            1 - _next(state) * (1 - np.exp(-((np.pi / 2) ** 2) / (2 * sd * sd)))
                        )
                    )
                    n0, n1, n2 = _frame_direction(
                        0.0, 0.0, 1.0, np.cos(theta), 2 * np.pi * _next(state)
                    )
                    dn = d0 * n0 + d1 * n1 + d2 * n2
                    if _next(state) < abs(dn):
                        a = np.degrees(np.arccos(min(1.0, abs(dn))))
                        ia = min(int(a), 89)
                        fa = a - ia
                        for j in range(W):
                            rl[j] = refl[sp, ia, j] * (1 - fa) + refl[sp, ia + 1, j] * fa
                        reflect = True
                        if transmits[sp]:
                            scalar_path = False
                            P = refl_mean[sp, ia] * (1 - fa) + refl_mean[sp, ia + 1] * fa
                            if _next(state) < P:
                                for j in range(W):
                                    w[j] *= rl[j] / P
                            else:
                                reflect = False
                                for j in range(W):
                                    w[j] *= (1 - rl[j]) / (1 - P)
                        else:
                            for j in range(W):
                                w[j] *= rl[j]
                            gw *= refl_mean[sp, ia] * (1 - fa) + refl_mean[sp, ia + 1] * fa
                            k += 1
                        if reflect:
                            d0, d1, d2 = d0 - 2 * dn * n0, d1 - 2 * dn * n1, d2 - 2 * dn * n2
                else:  # tentative scattering by pigments (spectral tracking)
                    scalar_path = False
                    for gi in range(G):
                        cos_t = d0 * det[gi, 0] + d1 * det[gi, 1] + d2 * det[gi, 2]
                        base = _hg_pdf(cos_t, g) * det_factor[gi]
                        for j in range(W):
                            score[gi, j] += w[j] * ratio[j] * base * np.exp(-det_att[gi, j] * depth)
                    # history-aware (Kutz et al. 2017): real with the weighted bands' share,
                    # which keeps the weights' mean over the bands. The bands' plain mean
                    # share made a band far from it carry a product of factors that spread
                    # over decades along a long path: TiO2 at 700 nm showed no primer
                    weighted, real = 0.0, 0.0
                    for j in range(W):
                        weighted += w[j]
                        real += w[j] * ratio[j]
                    p_scatter = real / weighted if weighted > 0 else 0.0
                    if _next(state) < p_scatter or p_scatter >= 1.0:
                        for j in range(W):
                            w[j] *= ratio[j] / p_scatter
                        if abs(g) > 1e-3:
                            t = (1 - g * g) / (1 - g + 2 * g * _next(state))
                            cos_t = (1 + g * g - t * t) / (2 * g)
                        else:
                            cos_t = 2 * _next(state) - 1
                        d0, d1, d2 = _frame_direction(d0, d1, d2, cos_t, 2 * np.pi * _next(state))
                    else:
                        for j in range(W):
                            w[j] *= (1 - ratio[j]) / (1 - p_scatter)
            # Russian roulette keeps the estimate unbiased while ending faint paths
            peak = w.max()
            if peak < 1e-3:
                if _next(state) < 0.1:
                    for j in range(W):
                        w[j] *= 10.0
                    gw *= 10.0
                else:
                    break
        for gi in range(G):
            for j in range(W):
                score_sum[gi, j] += score[gi, j]
                score_sq[gi, j] += score[gi, j] * score[gi, j]


@numba.njit(cache=True, parallel=True)
def _trace_round(chunks, per_chunk, done, photons, seed, optics, tallies):
    """Each chunk's photons ``done … done + ROUND_PHOTONS`` of its own (chunk c holds photons
    ``c·per_chunk …``, in order, whatever the rounds: the sums are those of one call)."""
    score_sum, score_sq, albedo_sum, albedo_sq, table_w, table_wl, capped = tallies
    for c in numba.prange(chunks):
        first = c * per_chunk + done
        count = min(ROUND_PHOTONS, per_chunk - done, photons - first)
        if count > 0:
            chunk = (score_sum[c], score_sq[c], albedo_sum[c], albedo_sq[c], table_w[c],
                     table_wl[c], capped[c])  # fmt: skip
            _trace(first, count, seed, optics, chunk)


def _exit_attenuation(layer: Layer, outgoing: NDArray) -> tuple[NDArray, NDArray]:
    """Extinction per unit depth along each detector direction: (spectral [G, W], flakes [G])."""
    mu = outgoing[:, 2]
    flakes = np.zeros(outgoing.shape[0])
    spectral = np.zeros((outgoing.shape[0], WAVELENGTHS.size))
    for s, rate in enumerate(layer.flake_rate[0]):
        projected = mean_projected_cosine(outgoing, float(layer.spreads[0, s]))
        if layer.flake_transmits[s]:
            # a pearl removes only what it reflects; its reflectance near the mean incidence
            angle = np.degrees(np.arccos(np.clip(projected, 0, 1)))
            R = layer.flake_reflectance[s, np.round(angle).astype(int)]
            spectral += rate * projected[:, None] * R
        else:
            flakes += rate * projected
    spectral += flakes[:, None] + layer.absorption[0] + layer.scattering[0]
    return spectral / mu[:, None], flakes / mu


def simulate(
    layer: Layer,
    geometries: ArrayLike,
    photons: int = 100_000,
    *,
    seed: int = 0,
    diffuse_illumination: bool = False,
    path_step: float = 0.5,
    chunks: int = 8,
    progress: Callable[[int], None] | None = None,
) -> MonteCarloResult:
    """Trace ``photons`` through the first formulation of ``layer`` for every geometry's
    detector (all geometries must share the illumination direction unless diffuse).

    ``diffuse_illumination`` replaces the collimated beam by a cosine-weighted one inside the
    coating (what Kubelka–Munk assumes). Deterministic for a given ``seed``. ``progress`` is
    called with the photons of each round as it ends (:data:`ROUND_PHOTONS`).
    """
    if photons < 2:
        raise ValueError(f"photons: expected at least 2, got {photons}")
    incoming, outgoing, T_in, T_out = interface_directions(geometries, layer.n)
    if not diffuse_illumination and not np.allclose(incoming, incoming[0]):
        raise ValueError("geometries: one Monte Carlo run needs one illumination direction")
    layer = layer[0]
    det_att, det_flake_att = _exit_attenuation(layer, outgoing)
    det_factor = T_out / (layer.n**2 * outgoing[:, 2])
    G, W = outgoing.shape[0], WAVELENGTHS.size
    chunks = max(1, min(chunks, photons))
    per_chunk = -(-photons // chunks)
    score_sum, score_sq = np.zeros((chunks, G, W)), np.zeros((chunks, G, W))
    albedo_sum, albedo_sq = np.zeros((chunks, W)), np.zeros((chunks, W))
    table_w = np.zeros((chunks, G, MAX_BOUNCES + 1, PATH_BINS))
    table_wl = np.zeros_like(table_w)
    capped = np.zeros((chunks, 1), dtype=np.int64)
    rates = np.ascontiguousarray(layer.flake_rate[0], dtype=float)
    if rates.size == 0:
        rates = np.zeros(1)
    refl = layer.flake_reflectance if rates.size == layer.flake_sd.size else np.zeros((1, 91, W))
    sds = layer.spreads[0] if layer.flake_sd.size else np.radians([10.0])
    transmits = layer.flake_transmits if layer.flake_transmits.size else np.zeros(1, bool)
    start = time.perf_counter()
    optics = (
        diffuse_illumination,
        np.ascontiguousarray(incoming[0]),
        1.0 if diffuse_illumination else float(T_in[0]),
        np.ascontiguousarray(outgoing),
        det_factor,
        det_att,
        det_flake_att,
        rates,
        np.asarray(sds, float),
        np.ascontiguousarray(refl),
        transmits.astype(np.bool_),
        np.ascontiguousarray(refl.mean(axis=2)),
        layer.absorption[0].copy(),
        layer.scattering[0].copy(),
        float(layer.asymmetry[0]),
        float(layer.film[0]),
        np.asarray(layer.primer, float),
        float(layer.n),
        float(path_step),
    )
    tallies = (score_sum, score_sq, albedo_sum, albedo_sq, table_w, table_wl, capped)
    left = np.clip(photons - np.arange(chunks) * per_chunk, 0, per_chunk)  # each chunk's
    for done in range(0, per_chunk, ROUND_PHOTONS):
        _trace_round(chunks, per_chunk, done, photons, np.uint64(seed), optics, tallies)
        if progress:
            progress(int(np.clip(left - done, 0, ROUND_PHOTONS).sum()))
    seconds = time.perf_counter() - start
    mean = score_sum.sum(0) / photons
    stderr = np.sqrt(np.maximum(score_sq.sum(0) / photons - mean**2, 0) / (photons - 1))
    a_mean = albedo_sum.sum(0) / photons
    a_err = np.sqrt(np.maximum(albedo_sq.sum(0) / photons - a_mean**2, 0) / (photons - 1))
    weight = table_w.sum(0) / photons
    length = np.divide(
        table_wl.sum(0) / photons, weight, out=np.zeros_like(weight), where=weight > 0
    )
    reflectance = _effective_reflectance(layer)
    return MonteCarloResult(
        brdf=mean,
        stderr=stderr,
        albedo=a_mean,
        albedo_stderr=a_err,
        table=PathTable(weight, length, reflectance),
        photons=photons,
        capped=int(capped.sum()),
        seconds=seconds,
    )


EFFECTIVE_INCIDENCE = 20
"""Incidence [degree] at which the spectral shape of a bounce is taken in path tables."""


def _effective_reflectance(layer: Layer) -> NDArray[np.float64]:
    """Rate-weighted reflectance of the aluminium species at :data:`EFFECTIVE_INCIDENCE`."""
    opaque = ~layer.flake_transmits
    rates = layer.flake_rate[0][opaque]
    if rates.size == 0 or rates.sum() <= 0:
        return np.ones(WAVELENGTHS.size)
    R = rates @ layer.flake_reflectance[opaque, EFFECTIVE_INCIDENCE] / rates.sum()
    return R / R.mean()
