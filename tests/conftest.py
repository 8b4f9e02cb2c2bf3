"""Shared fixtures: the real reference data in ../shared/data (skipped when absent)."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

import numpy as np
import pytest

from flakelab.core import Geometry, Measurement
from flakelab.core.spectra import WAVELENGTHS

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
MA_T12 = SHARED / "ma-t12"


@pytest.fixture(scope="session")
def ma_t12_dir() -> Path:
    if not MA_T12.is_dir():
        pytest.skip(f"reference data not found at {MA_T12} (../shared/data is absent)")
    return MA_T12


@pytest.fixture(scope="session")
def ma_t12_files(ma_t12_dir: Path) -> list[Path]:
    files = sorted(ma_t12_dir.glob("*.xlsx"))
    assert files, f"no MA-T12 exports in {ma_t12_dir}"
    return files


@pytest.fixture
def rich_measurement() -> Measurement:
    """A synthetic measurement using every field, including an out-of-plane geometry."""
    rng = np.random.default_rng(7)
    geometries = tuple(Geometry.parse(n) for n in ("45as15", "45as45", "45as110", "45as25az90"))
    return Measurement(
        sample='rich; sample, with "quotes"',
        geometries=geometries,
        wavelengths=WAVELENGTHS,
        reflectance=rng.uniform(0.01, 1.8, (4, 31)),
        texture={"Sa15": 12.5, "Si15": 9.25, "SG": 7.0, "G": 4.125},
        instrument="BYK-mac i",
        measured_at=datetime(2026, 3, 4, 5, 6, 7),
        stored_lab=rng.uniform([10, -40, -40], [100, 40, 40], (4, 3)),
        metadata={"shop": "north"},
    )
