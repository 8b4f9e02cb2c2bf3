"""The fast forward model: formulations → spectral BRDF ``[F, G, W]`` in microseconds each.

Three parts, summed (DESIGN.md §3):

* **Aluminium flakes, all bounces.** A dye changes no path, only its weight, so the
  dye-free Monte Carlo's detector weight w(k, L) by flake-bounce count k and path length L
  gives f(λ) = Σ w(k, L)·(q·s(λ))^k·e^{−κ(λ)L} for any dye (:class:`PathTable`). A layer of
  flakes alone is scale-free: in optical depth τ = σ_f·L, w depends only on the orientation
  spread and on σ_f·H. The shipped :class:`FlakeAtlas` stores, for each instrument geometry
  and a grid of spreads and σ_f·H, the double Laplace transform
  M(ρ, κ') = Σ w·e^{−ρk − κ'τ}; a formulation reads it at ρ = −ln(q·s(λ)), κ' = κ(λ)/σ_f,
  each aluminium of a blend at its own spread, weighted by its share of the flakes.
  Scattering pigments add their extinction to κ on this channel (scattered light leaves
  the flake paths; it returns through the diffuse term).
* **Pearls**, single collision: the semi-transparent platelets reflect once and let the
  rest through.
* **Diffuse light** from scattering pigments and the primer: Kubelka–Munk two-flux with the
  flakes as extra two-flux reflectors (S = σ_f·R̄, K = σ_f·(1 − R̄)), minus what the flake
  channel already holds (there the pigments' scattering is a loss along the flake paths),
  leaving the coating as a Lambertian source through the Fresnel top (internal diffuse
  reflection r_i = 0.596 at n = 1.5).

:func:`single_collision` is the hybrid paper's model as DESIGN.md writes it, kept to report
how far it is from the Monte Carlo.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from flakelab.core.geometry import INSTRUMENT_GEOMETRIES, Geometry
from flakelab.core.spectra import WAVELENGTHS
from flakelab.errors import FlakelabError
from flakelab.physics.kubelka_munk import km_coefficients, layer_reflectance
from flakelab.physics.layer import (
    REFLECTANCE_ANGLES,
    Layer,
    interface_directions,
    internal_diffuse_reflectance,
    orientation_pdf,
)
from flakelab.physics.montecarlo import EFFECTIVE_INCIDENCE, PathTable, simulate

__all__ = [
    "FlakeAtlas",
    "ATLAS_GEOMETRIES",
    "atlas_path",
    "load_atlas",
    "build_atlas",
    "single_collision",
    "predict",
    "reflectance_factor",
    "flake_geometry",
]

ATLAS_GEOMETRIES = INSTRUMENT_GEOMETRIES["ma-t12"]
"""Geometries the shipped atlas covers (MA-T12's twelve hold the BYK-mac and five-angle sets)."""
ATLAS_SPREADS = np.array([3.0, 5.0, 7.0, 10.0, 14.0, 20.0])
"""Orientation spreads [degree] of the atlas grid."""
ATLAS_DEPTHS = np.array([0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0])
"""Flake optical depths σ_f·H of the atlas grid; thinner layers scale linearly to zero."""
ATLAS_RHO = np.linspace(-0.1, 0.5, 13)
"""Per-bounce log attenuation ρ = −ln(q·s(λ)) of the atlas grid."""
ATLAS_KAPPA = np.concatenate([[0.0], np.geomspace(1e-3, 300.0, 47)])
"""Dye absorption per flake rate κ' = κ/σ_f of the atlas grid."""


def atlas_path() -> Path:
    return Path(__file__).resolve().parent.parent / "data" / "flake-atlas.npz"


@dataclass(frozen=True)
class FlakeAtlas:
    """``laplace[spread, depth, G, ρ, κ']``: Σ w·e^{−ρk − κ'τ} of a dye-free flake layer with
    σ_f = 1, per geometry name in ``geometries``; ``photons``/``seed`` of the runs behind it."""

    geometries: tuple[str, ...]
    laplace: NDArray[np.float64]
    photons: int
    seed: int

    def index(self, geometries: ArrayLike) -> NDArray[np.intp]:
        names = [g.name if isinstance(g, Geometry) else Geometry.parse(g).name for g in geometries]
        missing = [n for n in names if n not in self.geometries]
        if missing:
            raise FlakelabError(
                f"geometries: the fast model's flake atlas has no {', '.join(missing)} "
                f"(it covers {', '.join(self.geometries)}; "
                "rebuild with scripts/make_flake_atlas.py)"
            )
        return np.array([self.geometries.index(n) for n in names])

    def save(self, path: Path) -> None:
        """Write the atlas to ``path`` whole or not at all (a Ctrl-C there half-wrote the
        shipped file)."""
        from flakelab.io.records import write_atomically  # the file formats: not at start-up

        def write(temporary: Path) -> None:
            with temporary.open("wb") as handle:  # a handle: numpy adds ".npz" to a name
                np.savez_compressed(
                    handle,
                    geometries=np.array(self.geometries),
                    laplace=self.laplace.astype(np.float32),
                    photons=self.photons,
                    seed=self.seed,
                )

        write_atomically(path, write)


@cache
def load_atlas(path: Path | None = None) -> FlakeAtlas:
    """The shipped atlas (or one at ``path``)."""
    path = path or atlas_path()
    if not path.exists():
        raise FlakelabError(f"{path}: flake atlas missing; run scripts/make_flake_atlas.py")
    with np.load(path) as data:
        return FlakeAtlas(
            tuple(str(g) for g in data["geometries"]),
            data["laplace"].astype(float),
            int(data["photons"]),
            int(data["seed"]),
        )


def laplace_of_table(table: PathTable, rate: float) -> NDArray[np.float64]:
    """M[G, ρ, κ'] = Σ w·e^{−ρk − κ'·rate·L} of one path table."""
    k = np.arange(table.weight.shape[1])
    tau = table.length * rate  # [G, K, B]
    bounce = np.exp(-ATLAS_RHO[:, None] * k[None, :])  # [P, K]
    depth = np.exp(-ATLAS_KAPPA[:, None, None, None] * tau[None])  # [Q, G, K, B]
    weighted = np.einsum("gkb,qgkb->gkq", table.weight, depth)
    return np.einsum("pk,gkq->gpq", bounce, weighted)


def build_atlas(photons: int = 100_000, seed: int = 2026, progress=None) -> FlakeAtlas:
    """Run the dye-free Monte Carlo over the atlas grid (black primer, σ_f = 1, R = 1 shape)."""
    geometries = ATLAS_GEOMETRIES
    groups: dict[float, list[int]] = {}
    for i, name in enumerate(geometries):
        groups.setdefault(Geometry.parse(name).illumination, []).append(i)
    from flakelab.library.optics import flake_reflectance

    R = flake_reflectance(REFLECTANCE_ANGLES, WAVELENGTHS)[None]
    R = R / R[:, EFFECTIVE_INCIDENCE].mean()  # unit band-mean reflectance at 20°
    laplace = np.zeros(
        (ATLAS_SPREADS.size, ATLAS_DEPTHS.size, len(geometries), ATLAS_RHO.size, ATLAS_KAPPA.size)
    )
    zeros = np.zeros((1, WAVELENGTHS.size))
    run = 0
    for a, spread in enumerate(ATLAS_SPREADS):
        for b, depth in enumerate(ATLAS_DEPTHS):
            layer = Layer(
                np.array([[1.0]]),
                np.radians([spread]),
                R,
                np.array([False]),
                zeros,
                zeros,
                np.zeros(1),
                float(depth),
                np.zeros(WAVELENGTHS.size),
            )
            for indices in groups.values():
                run += 1
                result = simulate(layer, [geometries[i] for i in indices], photons, seed=seed + run)
                laplace[a, b, indices] = laplace_of_table(result.table, 1.0)
                if progress:
                    progress()
    return FlakeAtlas(tuple(geometries), laplace, photons, seed)


_LOG_CACHE: dict[tuple, NDArray] = {}


def _log_laplace(atlas: FlakeAtlas, index: tuple[int, ...]) -> NDArray:
    """log M of the atlas for some geometries ``[spread, depth, ρ, κ', G]`` (geometry last:
    :func:`_summed_lobes` reads every geometry of a corner at once), cached (interpolation is
    done in log)."""
    key = (id(atlas), index)
    if key not in _LOG_CACHE:
        log_m = np.log(np.maximum(atlas.laplace[:, :, list(index)], 1e-300))
        _LOG_CACHE[key] = np.ascontiguousarray(np.moveaxis(log_m, 2, -1))
    return _LOG_CACHE[key]


def _bracket(grid: NDArray, values: NDArray) -> tuple[NDArray, NDArray]:
    """Lower grid index and linear weight of each value (clipped to the grid)."""
    v = np.clip(values, grid[0], grid[-1])
    i = np.clip(np.searchsorted(grid, v, side="right") - 1, 0, grid.size - 2)
    return i, (v - grid[i]) / (grid[i + 1] - grid[i])


def _aluminium_channel(
    layer: Layer, atlas_index: NDArray, extinction: NDArray, atlas: FlakeAtlas
) -> NDArray:
    """All-bounce aluminium flake BRDF ``[F, G, W]`` from the atlas: each aluminium's lobe at
    its own orientation spread, weighted by its share of the flakes, all under the depth,
    mean bounce reflectance and attenuation of the whole layer. Single bounces are exactly
    such a sum; one lobe at the species' mean spread put a 5° VMP with a 15° fine aluminium
    6.3 ΔE00 from the Monte Carlo (12.7 at the worst geometry), the sum 1.1 (2.3; stop 115,
    docs/coating-optics.md)."""
    opaque = ~layer.flake_transmits
    rates = layer.flake_rate[:, opaque]  # [F, A]
    sigma = rates.sum(axis=1)  # [F]
    out = np.zeros((layer.size, atlas_index.size, WAVELENGTHS.size))
    f, a = np.nonzero(rates > 0)  # one lobe per formulation and aluminium in it
    if f.size == 0:
        return out
    share = rates[f, a] / sigma[f]
    spread = np.degrees(layer.spreads[:, opaque][f, a])
    bounce = rates @ layer.flake_reflectance[opaque, EFFECTIVE_INCIDENCE]  # [F, W]
    rho = -np.log(np.maximum(bounce[f] / sigma[f, None], 1e-9))  # [P, W]
    kappa = extinction[f] / sigma[f, None]
    depth = sigma[f] * layer.film[f]
    i_s, w_s = _bracket(ATLAS_SPREADS, spread)
    i_d, w_d = _bracket(np.log(ATLAS_DEPTHS), np.log(np.maximum(depth, ATLAS_DEPTHS[0])))
    thin = np.minimum(depth / ATLAS_DEPTHS[0], 1.0)
    i_r, w_r = _bracket(ATLAS_RHO, rho)  # [P, W]
    i_k, w_k = _bracket(np.log(ATLAS_KAPPA[1:]), np.log(np.maximum(kappa, ATLAS_KAPPA[1])))
    i_k = i_k + 1
    w_k = np.where(kappa < ATLAS_KAPPA[1], kappa / ATLAS_KAPPA[1], w_k)
    i_k = np.where(kappa < ATLAS_KAPPA[1], 0, i_k)
    log_m = _log_laplace(atlas, tuple(atlas_index))  # [spread, depth, ρ, κ', G]
    first = np.flatnonzero(np.r_[True, f[1:] != f[:-1]])  # each formulation's first lobe
    out[f[first]] = _summed_lobes(
        log_m, first, share * thin, i_s, w_s, i_d, w_d, i_r, w_r, i_k, w_k
    )
    return out


@numba.njit(cache=True)
def _summed_lobes(log_m, first, weight, i_s, w_s, i_d, w_d, i_r, w_r, i_k, w_k):
    """Each formulation's aluminium lobes ``[F', G, W]``, summed: lobe ``p`` (sorted by
    formulation, ``first`` the index of each formulation's first) is the multilinear
    interpolation of ``log_m[spread, depth, ρ, κ', G]`` at its spread and depth ``[P]`` and
    each wavelength's ρ and κ' ``[P, W]``, exponentiated and weighted by ``weight[P]``. One
    pass without temporaries: the 16 corners' fancy-indexed copies in numpy took most of a
    shade ratio's time in a match (2026-12-01); the exponentials and the sum in the same pass
    took a ninth off the aluminium channel in a ``--physics`` match (stop 117)."""
    P, W = i_r.shape
    G = log_m.shape[4]
    out = np.zeros((first.size, G, W))
    log_lobe = np.empty(G)
    for j in range(first.size):
        end = first[j + 1] if j + 1 < first.size else P
        for p in range(first[j], end):
            for w in range(W):
                log_lobe[:] = 0.0
                for ds in range(2):
                    ws = w_s[p] if ds else 1.0 - w_s[p]
                    for dd in range(2):
                        outer = ws * (w_d[p] if dd else 1.0 - w_d[p])
                        s, d = i_s[p] + ds, i_d[p] + dd
                        for dr in range(2):
                            wr = outer * (w_r[p, w] if dr else 1.0 - w_r[p, w])
                            r = i_r[p, w] + dr
                            for dk in range(2):
                                corner = wr * (w_k[p, w] if dk else 1.0 - w_k[p, w])
                                k = i_k[p, w] + dk
                                for g in range(G):
                                    log_lobe[g] += corner * log_m[s, d, r, k, g]
                for g in range(G):
                    out[j, g, w] += np.exp(log_lobe[g]) * weight[p]
    return out


def flake_geometry(geometries: ArrayLike, n: float) -> dict[str, NDArray]:
    """Inside cosines, half-vector tilt, incidence on that flake and Fresnel factors of
    geometries (names or :class:`Geometry`); read-only, computed once per set and index (a
    fifth of a small batch's prediction time when computed afresh)."""
    return _flake_geometry(tuple(geometries), float(n))


@cache
def _flake_geometry(geometries: tuple[Geometry | str, ...], n: float) -> dict[str, NDArray]:
    incoming, outgoing, T_in, T_out = interface_directions(geometries, n)
    half = outgoing - incoming
    half /= np.linalg.norm(half, axis=-1, keepdims=True)
    cos_inc = np.abs(np.sum(incoming * half, axis=-1))
    geo = {
        "incoming": incoming,
        "outgoing": outgoing,
        "mu_in": -incoming[:, 2],
        "mu_out": outgoing[:, 2],
        "theta_flake": np.arccos(np.clip(half[:, 2], -1, 1)),
        "theta_inc": np.degrees(np.arccos(np.clip(cos_inc, 0, 1))),
        "interface": T_in * T_out / n**2,
    }
    for value in geo.values():
        value.setflags(write=False)
    return geo


def _table_at(table: NDArray, degrees: NDArray) -> NDArray:
    """Reflectance tables ``[S, 91, W]`` at incidences ``[G]`` → ``[S, G, W]``."""
    i = np.clip(degrees.astype(int), 0, 89)
    f = (degrees - i)[None, :, None]
    return table[:, i] * (1 - f) + table[:, i + 1] * f


def single_collision(layer: Layer, geometries: ArrayLike) -> NDArray[np.float64]:
    """The single-collision model of DESIGN.md §3 (hybrid paper), ``[F, G, W]``:

    f = T_i·T_o/n² · Σ_s σ_s R_s(θ_inc) D_s(θ_flake) / (4μi'μo') · (1 − e^{−(2σ_f + κm)H}) /
    (2σ_f + κm), m = 1/μi' + 1/μo'.
    """
    geo = flake_geometry(geometries, layer.n)
    m = 1 / geo["mu_in"] + 1 / geo["mu_out"]
    D = orientation_pdf(geo["theta_flake"][None, None, :], layer.spreads[..., None])  # [F, S, G]
    R = _table_at(layer.flake_reflectance, geo["theta_inc"])  # [S, G, W]
    lobe = np.einsum("fs,fsg,sgw->fgw", layer.flake_rate, D, R)
    lobe /= (4 * geo["mu_in"] * geo["mu_out"])[None, :, None]
    X = 2 * layer.flake_rate.sum(1)[:, None, None] + layer.absorption[:, None, :] * m[None, :, None]
    H = layer.film[:, None, None]
    depth = np.where(X > 0, -np.expm1(-X * H) / np.maximum(X, 1e-300), H)
    return geo["interface"][None, :, None] * lobe * depth


def _pearl_channel(layer: Layer, geo: dict, extinction_in: NDArray, extinction_out: NDArray):
    """Single-collision pearls ``[F, G, W]`` under the attenuation of everything else (only
    the formulations that hold pearls computed: the others' is zero)."""
    pearls = layer.flake_transmits
    rates = layer.flake_rate[:, pearls]
    rows = np.flatnonzero(np.any(rates > 0, axis=1))
    if rows.size == 0:
        return 0.0
    D = orientation_pdf(geo["theta_flake"][None, None, :], layer.spreads[rows][:, pearls, None])
    R = _table_at(layer.flake_reflectance[pearls], geo["theta_inc"])
    lobe = np.einsum("fs,fsg,sgw->fgw", rates[rows], D, R)
    lobe /= (4 * geo["mu_in"] * geo["mu_out"])[None, :, None]
    X = extinction_in[rows] + extinction_out[rows]
    depth = -np.expm1(-X * layer.film[rows, None, None]) / np.maximum(X, 1e-300)
    out = np.zeros((layer.size, *lobe.shape[1:]))
    out[rows] = geo["interface"][None, :, None] * lobe * depth
    return out


def _flake_two_flux(layer: Layer) -> tuple[NDArray, NDArray]:
    """Flakes as two-flux reflectors: (K, S) ``[F, W]`` from their rates and reflectance."""
    R = layer.flake_reflectance[:, EFFECTIVE_INCIDENCE]  # [S, W]
    absorbed = np.where(layer.flake_transmits[:, None], 0.0, 1 - R)
    return layer.flake_rate @ absorbed, layer.flake_rate @ R


def _diffuse_channel(layer: Layer, geo: dict, K_fl: NDArray, S_fl: NDArray) -> NDArray:
    """Lambertian light from scattering pigments and the primer ``[F, G, W]``: the two-flux
    light of everything, less that of the flakes alone as the flake channels hold it, which
    loses what the pigments scatter (reduced coefficient) along the flake paths' own length,
    (1/μi' + 1/μo')/2 per flux. Leaving that loss out gave back little of the light 3 % TiO2
    scatters out of a VMP's paths (45as110 at 550 nm: 0.026 against the Monte Carlo's 0.142,
    now 0.178); counting it at the diffuse flux's length (2 per flux) twice over (0.217).
    ``K_fl``, ``S_fl``: the flakes as two-flux reflectors (:func:`_flake_two_flux`)."""
    K, S = km_coefficients(layer.absorption, layer.scattering, layer.asymmetry[:, None])
    H = layer.film[:, None]
    everything = layer_reflectance(K + K_fl, S + S_fl, H, layer.primer[None])[:, None, :]
    flakes_only = _flakes_only(layer, K + K_fl, S_fl, geo)
    r_i = internal_diffuse_reflectance(layer.n)
    body = everything / (1 - r_i * everything) - flakes_only / (1 - r_i * flakes_only)
    return geo["interface"][None, :, None] * np.maximum(body, 0.0) / np.pi


def _flakes_only(layer: Layer, K: NDArray, S_fl: NDArray, geo: dict) -> NDArray:
    """The two-flux light of the flakes alone ``[F, G, W]`` (absorption ``K`` of everything,
    scattering ``S_fl`` of the flakes), losing what the pigments scatter along each
    geometry's flake paths. Where no pigment scatters that loss is nil and the light the
    same at every geometry: computed once (two of five formulations of the world; the
    per-geometry layers had been half the cost of the diffuse channel)."""
    out = np.empty((layer.size, geo["mu_in"].size, K.shape[1]))
    H = layer.film[:, None]
    reduced = layer.reduced_scattering
    scatters = np.any(reduced > 0, axis=1)
    calm = ~scatters
    out[calm] = layer_reflectance(K[calm], S_fl[calm], H[calm], 0.0)[:, None, :]
    path = (1 / geo["mu_in"] + 1 / geo["mu_out"]) / 2  # [G]
    scattered = reduced[scatters, None, :] * path[None, :, None]
    out[scatters] = layer_reflectance(
        K[scatters, None, :] + scattered, S_fl[scatters, None, :], H[scatters, :, None], 0.0
    )
    return out


PREDICT_BATCH = 2048
"""Formulations evaluated together (bounds the memory of large batches)."""


def predict(layer: Layer, geometries: ArrayLike, atlas: FlakeAtlas | None = None) -> NDArray:
    """Spectral BRDF ``[F, G, W]`` [1/sr] of every formulation in ``layer`` (fast model)."""
    atlas = atlas or load_atlas()
    geometries = list(geometries)
    if layer.size > PREDICT_BATCH:
        return np.concatenate(
            [
                predict(layer[start : start + PREDICT_BATCH], geometries, atlas)
                for start in range(0, layer.size, PREDICT_BATCH)
            ]
        )
    geo = flake_geometry(geometries, layer.n)
    # forward-scattered light stays near the specular flake paths; the rest leaves them
    extinction = layer.absorption + layer.reduced_scattering
    aluminium = _aluminium_channel(layer, atlas.index(geometries), extinction, atlas)
    K_fl, S_fl = _flake_two_flux(layer)  # per depth: what flakes absorb plus reflect
    flakes = (K_fl + S_fl)[:, None, :]
    ext_in = flakes + extinction[:, None, :] / geo["mu_in"][None, :, None]
    ext_out = flakes + extinction[:, None, :] / geo["mu_out"][None, :, None]
    pearls = _pearl_channel(layer, geo, ext_in, ext_out)
    return aluminium + pearls + _diffuse_channel(layer, geo, K_fl, S_fl)


def reflectance_factor(layer: Layer, geometries: ArrayLike) -> NDArray:
    """Reflectance factors ``[F, G, W]`` of ``layer``: π·BRDF, what an instrument reads
    against the perfect diffuser (whose BRDF is 1/π)."""
    return np.pi * predict(layer, geometries)
