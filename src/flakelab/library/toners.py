"""A shop's toner library: aluminium flakes, coloured pigments, pearls, binder and clearcoat.

Every toner is a small frozen dataclass checked when built; a :class:`Library` holds them
by name and turns recipes into validated mass fractions. Spectra live on the storage grid
(:data:`~flakelab.core.spectra.WAVELENGTHS`). Any toner may give its ``density_g_ml``
[g/mL] as sold, from which a can ordered by volume is weighed (:meth:`Library.densities`).
Files: ``flakelab.io.read_library``.
"""

from __future__ import annotations

import unicodedata
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import MISSING, dataclass, field, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from flakelab.core import wording
from flakelab.core.documents import LIBRARY_FORMAT
from flakelab.core.geometry import N_BINDER
from flakelab.core.spectra import WAVELENGTHS
from flakelab.core.units import is_number
from flakelab.core.wording import counted
from flakelab.errors import FlakelabError, shown
from flakelab.library.optics import SUBSTRATE_INDEX

__all__ = [
    "AluminiumFlake",
    "Pigment",
    "Pearl",
    "Binder",
    "Library",
    "LibraryError",
    "check_toners",
    "did_you_mean",
    "TONER_KINDS",
    "PAINT_FAMILIES",
    "SUM_TOLERANCE",
    "HIDING_COEFFICIENT",
    "FLAKE_RADIUS_MIN_UM",
    "FLAKE_THICKNESS_MIN_UM",
    "ORIENTATION_SD_MIN_DEG",
    "DENSITY_RANGE_G_ML",
]

SUM_TOLERANCE = 1e-6
"""Relative tolerance on recipe amounts summing to the can [-]."""

MAX_COEFFICIENT = 1e4
"""Largest specific absorption or scattering a library may give [1/µm per unit mass
fraction]: light 0.1 nm deep in a full-strength layer, about 800 times the demo library's
strongest (carbon black's K, 13). Larger values only come from a typing slip, and overflow
the optics (a value of 1e308 made the prediction NaN)."""
FLAKE_RADIUS_MIN_UM = 1.0
"""Smallest flake radius a library may give [µm]. The flake model reflects by geometric
optics, each flake a small mirror, which holds for flakes much wider than the light's
wavelength (0.4–0.7 µm); the demo's smallest is 5 µm. A radius of 1e-320 µm counted
infinitely many flakes in the texture readings (NaN)."""
FLAKE_THICKNESS_MIN_UM = 0.01
"""Thinnest aluminium flake a library may give [µm]: under about 10 nm aluminium lets
light through, which the mirror model ignores (vacuum-metallised flakes, the thinnest made,
are 20–50 nm; the demo's thinnest 50 nm). 1e-300 µm overflowed the flakes' layer."""
ORIENTATION_SD_MIN_DEG = 1.0
"""Narrowest spread of flake normals a library may give [degree], below any sprayed
coating's (the demo's best aligned spread 5°). 1e-300° made a pearl's prediction NaN."""
DENSITY_RANGE_G_ML = (0.5, 5.0)
"""Densities a toner may give [g/mL]: mixing toners as sold are about 0.9 (aluminium pastes in
solvent) to 1.6 (titanium dioxide whites). Outside this range the number is in another unit,
such as 980 for g/L."""
HIDING_COEFFICIENT = 1.0
"""Specific scattering (mean) or absorption (least) [1/µm per unit mass fraction] from which
a pigment hides the primer by itself (:attr:`Pigment.hides`). The demo library splits
cleanly at it: TiO2, the opaque iron oxides and BiVO4 scatter 1.6–9.3, carbon black absorbs
12.8 at least; every other pigment scatters below 0.2 and absorbs below 0.5 somewhere."""


class LibraryError(FlakelabError):
    """A toner library or a recipe that is wrong: names the toner, the field and the problem."""


def check_toners(names: Iterable[str], toners: Sequence[str], where: str = "") -> None:
    """Refuse the first of ``names`` that is not one of ``toners`` (a library's or a model's),
    naming the nearest that is; ``where`` (a file, an option) begins the message."""
    for name in names:
        if name not in toners:
            raise LibraryError(
                f"{where}{name!r} is not a toner of the library{did_you_mean(name, toners)}"
            )


def did_you_mean(name: str, toners: Iterable[str]) -> str:
    """ " (did you mean 'Phthalo blue GS'?)": the toner of ``toners`` that ``name`` most
    likely means, for the message that refuses it; "" where none is near. The same name but
    for case and spaces ("phthalo blue gs", a spreadsheet's non-breaking space) comes first,
    then the closest spelling; before, the spelling alone was compared, and a name typed in
    lower case or copied from a spreadsheet was refused without a hint."""
    return wording.did_you_mean(name, toners, _toner_key)


def _toner_key(name: str) -> str:
    return " ".join(unicodedata.normalize("NFKC", name).casefold().split())


def _positive(
    owner: str, name: str, value: float, *, lower: float = 0.0, upper: float | None = None
) -> None:
    if not (is_number(value) and np.isfinite(value) and value > 0):
        raise LibraryError(f"{owner}: {name}: expected a positive number, got {shown(value)}")
    if value < lower:
        raise LibraryError(f"{owner}: {name}: expected at least {lower}, got {value!r}")
    if upper is not None and value > upper:
        raise LibraryError(f"{owner}: {name}: expected at most {upper}, got {value!r}")


def _density(owner: str, value: float | None) -> None:
    """A toner's density as sold, if given: how a can by volume is weighed."""
    if value is not None:
        lower, upper = DENSITY_RANGE_G_ML
        _positive(owner, "density_g_ml", value, lower=lower, upper=upper)


def _spread(owner: str, value: float) -> None:
    _positive(owner, "orientation_sd_deg", value, lower=ORIENTATION_SD_MIN_DEG, upper=45)


def _check_fields(where: str, settings: Mapping[str, Any], kind: type) -> None:
    """A file's settings for a dataclass ``kind``: none it lacks, every one it needs."""
    allowed = sorted(f.name for f in fields(kind))
    if unknown := sorted(set(settings) - set(allowed)):
        raise LibraryError(f"{where}: unknown fields {unknown} (expected {allowed})")
    required = [
        f.name for f in fields(kind) if f.default is MISSING and f.default_factory is MISSING
    ]
    if missing := sorted(set(required) - set(settings)):
        raise LibraryError(f"{where}: missing fields {missing}")


def _is_storage_grid(wavelengths: Any) -> bool:
    try:
        return list(map(float, wavelengths)) == WAVELENGTHS.tolist()
    except (TypeError, ValueError):
        return False


def _spectrum(owner: str, name: str, values: Any, upper: float = MAX_COEFFICIENT) -> NDArray:
    """A toner's spectrum on the storage grid: finite numbers from 0 to ``upper``."""
    expected = f"{WAVELENGTHS.size} numbers (400–700 nm, 10 nm)"
    if values is None:
        raise LibraryError(f"{owner}: {name}: missing spectrum ({expected})")
    if not isinstance(values, list | tuple | np.ndarray):
        raise LibraryError(f"{owner}: {name}: expected {expected}, got {shown(values)}")
    if len(values) != WAVELENGTHS.size:
        got = counted(len(values), "value")
        raise LibraryError(f"{owner}: {name}: expected {expected}, got {got}")
    if not isinstance(values, np.ndarray):
        for value, wavelength in zip(values, WAVELENGTHS, strict=True):
            if not is_number(value):
                raise LibraryError(
                    f"{owner}: {name}, {wavelength:g} nm: expected a number, got {shown(value)}"
                )
    array = np.asarray(values, dtype=float)
    wrong = ~(np.isfinite(array) & (array >= 0) & (array <= upper))
    if np.any(wrong):
        i = int(np.argmax(wrong))
        raise LibraryError(
            f"{owner}: {name}, {WAVELENGTHS[i]:g} nm: expected a value from 0 to {upper:g}, "
            f"got {array[i]!r}"
        )
    array.setflags(write=False)
    return array


def _text(owner: str, name: str, value: Any) -> None:
    if not isinstance(value, str):
        raise LibraryError(f"{owner}: {name}: expected a text, got {shown(value)}")


@dataclass(frozen=True)
class AluminiumFlake:
    """Aluminium flake toner: disks of radius ``radius_um`` [µm] and ``thickness_um`` [µm],
    normals spread around the surface normal with s.d. ``orientation_sd_deg`` [degree];
    ``surface_quality`` [0–1] scales the specular part (1 = mirror-like "silver dollar",
    lower = "cornflake" with rough edges). ``volume_fraction`` [-] is the flakes' share of
    the dry film when the recipe is this toner alone (amounts scale it down in a mix)."""

    name: str
    radius_um: float
    thickness_um: float
    orientation_sd_deg: float
    surface_quality: float = 1.0
    volume_fraction: float = 0.13
    description: str = ""
    density_g_ml: float | None = None
    kind = "aluminium"

    def __post_init__(self) -> None:
        _positive(self.name, "radius_um", self.radius_um, lower=FLAKE_RADIUS_MIN_UM, upper=100)
        _positive(
            self.name, "thickness_um", self.thickness_um, lower=FLAKE_THICKNESS_MIN_UM, upper=2
        )
        _spread(self.name, self.orientation_sd_deg)
        _positive(self.name, "surface_quality", self.surface_quality, upper=1)
        _positive(self.name, "volume_fraction", self.volume_fraction, upper=0.6)
        _text(self.name, "description", self.description)
        _density(self.name, self.density_g_ml)


@dataclass(frozen=True)
class Pigment:
    """Coloured pigment or dye: specific absorption K(λ) and scattering S(λ) per unit mass
    fraction [1/µm], Henyey–Greenstein asymmetry ``g`` [−1, 1]."""

    name: str
    family: str
    absorption: NDArray[np.float64]
    scattering: NDArray[np.float64]
    g: float = 0.0
    description: str = ""
    density_g_ml: float | None = None
    kind = "pigment"

    def __post_init__(self) -> None:
        object.__setattr__(self, "absorption", _spectrum(self.name, "absorption", self.absorption))
        object.__setattr__(self, "scattering", _spectrum(self.name, "scattering", self.scattering))
        if not np.any(self.absorption > 0) and not np.any(self.scattering > 0):
            raise LibraryError(f"{self.name}: absorption and scattering are both all zero")
        if not (is_number(self.g) and -1 < self.g < 1):
            raise LibraryError(f"{self.name}: g: expected a value in (−1, 1), got {shown(self.g)}")
        _text(self.name, "family", self.family)
        _text(self.name, "description", self.description)
        _density(self.name, self.density_g_ml)

    @property
    def transparent(self) -> bool:
        """True for a dye-like toner that absorbs but does not scatter."""
        return not np.any(self.scattering > 0)

    @property
    def hides(self) -> bool:
        """True for a pigment that hides a basecoat's primer on its own: a white or an
        opaque inorganic that scatters (mean S ≥ ``HIDING_COEFFICIENT``), or a black that
        absorbs across the whole spectrum (least K ≥ ``HIDING_COEFFICIENT``)."""
        return bool(self.scattering.mean() >= HIDING_COEFFICIENT or self.black)

    @property
    def black(self) -> bool:
        """True for a black: it absorbs across the whole spectrum (least K ≥
        ``HIDING_COEFFICIENT``)."""
        return bool(self.absorption.min() >= HIDING_COEFFICIENT)

    @property
    def whiteness(self) -> float:
        """Share of scattering in extinction, S / (K + S) averaged over wavelength: 1 for
        a white, 0 for a dye."""
        return float(self.scattering.mean() / (self.absorption + self.scattering).mean())


@dataclass(frozen=True)
class Pearl:
    """Interference pigment: TiO2 coating of ``coating_nm`` [nm] on a platelet substrate
    (``mica``, ``alumina``, ``silica``) of ``substrate_nm`` [nm]; geometry and
    ``volume_fraction`` as for :class:`AluminiumFlake`."""

    name: str
    coating_nm: float
    substrate: str
    substrate_nm: float
    radius_um: float
    orientation_sd_deg: float
    volume_fraction: float = 0.10
    description: str = ""
    density_g_ml: float | None = None
    kind = "pearl"

    @property
    def thickness_um(self) -> float:
        return (self.substrate_nm + 2 * self.coating_nm) / 1000

    def __post_init__(self) -> None:
        _positive(self.name, "volume_fraction", self.volume_fraction, upper=0.6)
        _positive(self.name, "coating_nm", self.coating_nm, upper=1000)
        _positive(self.name, "substrate_nm", self.substrate_nm, upper=5000)
        _positive(self.name, "radius_um", self.radius_um, lower=FLAKE_RADIUS_MIN_UM, upper=100)
        _spread(self.name, self.orientation_sd_deg)
        if not isinstance(self.substrate, str) or self.substrate not in SUBSTRATE_INDEX:
            raise LibraryError(
                f"{self.name}: substrate: expected one of {', '.join(SUBSTRATE_INDEX)}, "
                f"got {shown(self.substrate)}"
            )
        _text(self.name, "description", self.description)
        _density(self.name, self.density_g_ml)


@dataclass(frozen=True)
class Binder:
    """Binder and clearcoat: refractive index, basecoat thickness [µm] and the primer's
    diffuse reflectance R_g(λ)."""

    refractive_index: float = N_BINDER
    thickness_um: float = 15.0
    primer_reflectance: NDArray[np.float64] = field(
        default_factory=lambda: np.full(WAVELENGTHS.size, 0.05)
    )

    def __post_init__(self) -> None:
        _positive("binder", "refractive_index", self.refractive_index, upper=3)
        if self.refractive_index < 1:
            raise LibraryError(
                f"binder: refractive_index: expected ≥ 1, got {self.refractive_index}"
            )
        _positive("binder", "thickness_um", self.thickness_um, upper=200)
        primer = _spectrum("binder", "primer_reflectance", self.primer_reflectance, upper=1)
        object.__setattr__(self, "primer_reflectance", primer)


Toner = AluminiumFlake | Pigment | Pearl
TONER_KINDS: dict[str, type] = {"aluminium": AluminiumFlake, "pigment": Pigment, "pearl": Pearl}
PAINT_FAMILIES = ("metallic", "pearl", "solid")
"""What a recipe makes (:meth:`Library.paint_families`): the generator's formulation kinds too."""


@dataclass(frozen=True)
class Library:
    """Toners by name plus the binder; the order of ``toners`` is the recipe vector order."""

    name: str
    toners: tuple[Toner, ...]
    binder: Binder = field(default_factory=Binder)
    synthetic: bool = False
    description: str = ""

    def __post_init__(self) -> None:
        if not self.toners:
            raise LibraryError(f"library {self.name!r}: expected at least one toner, got none")
        names = [t.name for t in self.toners]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise LibraryError(f"library {self.name!r}: toner names appear twice: {duplicates}")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.toners)

    @property
    def effect(self) -> NDArray:
        """Which toners are effect toners (aluminium, pearl), in the recipe vector order."""
        return np.array([t.kind != "pigment" for t in self.toners])

    @property
    def flake_radii_um(self) -> NDArray:
        """Radius [µm] of each flake species, the effect toners in recipe order (the columns
        of a layer's flake rates)."""
        return np.array([t.radius_um for t in self.toners if t.kind != "pigment"])

    def paint_families(self, fractions: ArrayLike) -> NDArray[np.str_]:
        """The paint family of each recipe ``fractions[N, T]`` (library order): "pearl" with
        any pearl in it, "solid" without effect toners, else "metallic"."""
        used = np.atleast_2d(np.asarray(fractions, dtype=float)) > 0
        kinds = np.array([t.kind for t in self.toners])
        pearl = used[:, kinds == "pearl"].any(axis=1)
        solid = ~used[:, kinds != "pigment"].any(axis=1)
        return np.where(pearl, "pearl", np.where(solid, "solid", "metallic"))

    def densities(self, names: Iterable[str]) -> dict[str, float]:
        """The density [g/mL] of each named toner, for a can ordered by volume; a
        :class:`LibraryError` naming those the library gives none for."""
        toners = [self[n] for n in names]
        if missing := [t.name for t in toners if t.density_g_ml is None]:
            raise LibraryError(
                f"library {self.name!r}: no density_g_ml for {', '.join(missing)}, so a can "
                "by volume cannot be weighed; give the can by mass (e.g. 250g)"
            )
        return {t.name: float(t.density_g_ml) for t in toners}

    def __getitem__(self, name: str) -> Toner:
        for toner in self.toners:
            if toner.name == name:
                return toner
        raise LibraryError(
            f"library {self.name!r}: unknown toner {name!r}{did_you_mean(name, self.names)}"
        )

    def solid_bases(self, pool: Iterable[int] | None = None) -> tuple[int | None, list[int]]:
        """The whitest pigment of ``pool`` (indices, default every toner) that hides, and the
        others that hide (:attr:`Pigment.hides`): a solid's bases, and the white with which
        ISO 787-24 reduces a pigment."""
        pool = range(len(self.toners)) if pool is None else pool
        hiding = [i for i in pool if self.toners[i].kind == "pigment" and self.toners[i].hides]
        white = max(hiding, key=lambda i: self.toners[i].whiteness, default=None)
        return white, [i for i in hiding if i != white]

    def of_kind(self, kind: str) -> tuple[Toner, ...]:
        if kind not in TONER_KINDS:
            raise LibraryError(
                f"expected a toner kind among {', '.join(TONER_KINDS)}, got {kind!r}"
            )
        return tuple(t for t in self.toners if t.kind == kind)

    def fractions(
        self, amounts: Mapping[str, float], *, total: float | None = None
    ) -> NDArray[np.float64]:
        """Mass fractions in library order from a recipe ``{toner: amount}``.

        ``total`` is the can's content in the amounts' unit; when given, the amounts must sum
        to it. Unknown toners, negative or non-finite amounts and an empty recipe are errors.

        Examples
        --------
        >>> flakes = (AluminiumFlake("AL1", 10, 0.3, 10), AluminiumFlake("AL2", 20, 0.4, 12))
        >>> lib = Library("demo", flakes)
        >>> lib.fractions({"AL2": 30.0, "AL1": 10.0}, total=40.0).tolist()
        [0.25, 0.75]
        """
        if not amounts:
            raise LibraryError("recipe: expected at least one toner amount, got none")
        vector = np.zeros(len(self.toners))
        names = self.names
        for name, amount in amounts.items():
            if name not in names:
                raise LibraryError(
                    f"recipe: unknown toner {name!r} in library {self.name!r}"
                    + did_you_mean(name, names)
                )
            if not (isinstance(amount, int | float) and np.isfinite(amount)) or amount < 0:
                raise LibraryError(
                    f"recipe: {name}: expected a non-negative amount, got {amount!r}"
                )
            vector[names.index(name)] = amount
        amount_sum = vector.sum()
        if amount_sum <= 0:
            raise LibraryError("recipe: amounts sum to zero")
        if total is not None and not np.isclose(amount_sum, total, rtol=SUM_TOLERANCE, atol=0):
            raise LibraryError(
                f"recipe: amounts sum to {amount_sum:g}, expected the can's {total:g}"
            )
        return vector / amount_sum

    def to_dict(self) -> dict[str, Any]:
        def toner_dict(t: Toner) -> dict[str, Any]:
            data = {"kind": t.kind}
            for f in fields(t):
                value = getattr(t, f.name)
                if value is not None:  # an optional field not given
                    data[f.name] = value.tolist() if isinstance(value, np.ndarray) else value
            return data

        return {
            "format": LIBRARY_FORMAT,
            "version": 1,
            "name": self.name,
            "synthetic": self.synthetic,
            "description": self.description,
            "wavelengths": WAVELENGTHS.tolist(),
            "binder": {
                "refractive_index": self.binder.refractive_index,
                "thickness_um": self.binder.thickness_um,
                "primer_reflectance": self.binder.primer_reflectance.tolist(),
            },
            "toners": [toner_dict(t) for t in self.toners],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "library") -> Library:
        """Build and check a library from its file structure (see :meth:`to_dict`)."""
        if data.get("format") != LIBRARY_FORMAT:
            raise LibraryError(
                f"{source}: expected format {LIBRARY_FORMAT!r}, got {data.get('format')!r}"
            )
        wavelengths = data.get("wavelengths", WAVELENGTHS.tolist())
        if not _is_storage_grid(wavelengths):
            raise LibraryError(f"{source}: wavelengths: expected 400–700 nm in 10 nm steps")
        items = data.get("toners", [])
        if not isinstance(items, list) or not all(isinstance(t, Mapping) for t in items):
            raise LibraryError(f"{source}: toners: expected a list of toner objects")
        toners = []
        for i, item in enumerate(items):
            where = f"{source}: toners[{i}] ({item.get('name', '?')})"
            if not isinstance(item.get("name"), str) or not item["name"].strip():
                raise LibraryError(f"{where}: name: expected a text, got {item.get('name')!r}")
            kind = item.get("kind")
            if not isinstance(kind, str) or kind not in TONER_KINDS:
                raise LibraryError(
                    f"{where}: kind: expected one of {', '.join(TONER_KINDS)}, got {shown(kind)}"
                )
            cls_ = TONER_KINDS[kind]
            settings = {k: v for k, v in item.items() if k != "kind"}
            _check_fields(where, settings, cls_)
            try:
                toners.append(cls_(**settings))
            except LibraryError as error:
                raise LibraryError(f"{source}: {error}") from None
        binder = data.get("binder", {})
        if not isinstance(binder, Mapping):
            raise LibraryError(f"{source}: binder: expected an object")
        _check_fields(f"{source}: binder", binder, Binder)
        try:
            return cls(
                name=str(data.get("name", source)),
                toners=tuple(toners),
                binder=Binder(**binder),
                synthetic=bool(data.get("synthetic", False)),
                description=str(data.get("description", "")),
            )
        except LibraryError as error:
            raise LibraryError(f"{source}: {error}") from None
