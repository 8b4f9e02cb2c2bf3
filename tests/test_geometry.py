"""Geometry names, directions and flake-based parameters."""

from __future__ import annotations

import numpy as np
import pytest

from flakelab.core.geometry import (
    INSTRUMENT_GEOMETRIES,
    Geometry,
    directions,
    directions_at,
    flake_angles,
    flake_angles_at,
    instrument_geometries,
    parse_geometries,
    refract_into_coating,
)


@pytest.mark.parametrize(
    "name", ["45as15", "45as-15", "15as80", "45as110", "45as25az90", "45as25az-45"]
)
def test_names_round_trip(name):
    assert Geometry.parse(name).name == name


def test_name_conventions_of_astm_e2194():
    assert Geometry.parse("45as45").viewing == 0  # along the normal
    assert Geometry.parse("45as110").viewing == -65  # on the light's side
    assert Geometry.parse("45as-15").viewing == 60  # beyond specular
    light, view = directions(["45as110"])
    assert light[0, 0] < 0 and view[0, 0] < 0  # both on the −x side
    np.testing.assert_allclose(np.degrees(np.arccos(view[0, 2])), 65)


def test_flake_angles_hand_computed_45as15():
    theta_flake, theta_inc = flake_angles(["45as15"], n=1.5)
    theta_i = np.degrees(np.arcsin(np.sin(np.radians(45)) / 1.5))  # 28.13°
    theta_v = np.degrees(np.arcsin(np.sin(np.radians(30)) / 1.5))  # 19.47°
    assert theta_flake[0] == pytest.approx((theta_i - theta_v) / 2)
    assert theta_inc[0] == pytest.approx((theta_i + theta_v) / 2)
    assert round(theta_flake[0], 1) == 4.3 and round(theta_inc[0], 1) == 23.8


def test_flake_angles_symmetries():
    # specular: the flake lies flat and the incidence is the refracted illumination angle
    theta_flake, theta_inc = flake_angles(["45as0"])
    assert theta_flake[0] == pytest.approx(0, abs=1e-9)
    assert theta_inc[0] == pytest.approx(np.degrees(np.arcsin(np.sin(np.radians(45)) / 1.5)))
    # reciprocity: swapping lamp and detector (45as15 ↔ 30as-15) changes nothing
    np.testing.assert_allclose(flake_angles(["45as15"]), flake_angles(["30as-15"]))
    # mirror-image out-of-plane geometries agree; az0 is the in-plane geometry
    np.testing.assert_allclose(flake_angles(["45as25az60"]), flake_angles(["45as25az-60"]))
    np.testing.assert_allclose(flake_angles(["45as25az0"]), flake_angles(["45as25"]))
    # without refraction the flake tilt is half the aspecular angle
    np.testing.assert_allclose(flake_angles(["45as15", "45as45"], n=1.0)[0], [7.5, 22.5])
    # θ_flake grows monotonically from specular toward the lamp (BYK-mac set)
    tilt = flake_angles(instrument_geometries("byk-mac-i")[1:])[0]
    assert np.all(np.diff(tilt) > 0)


def test_flake_angles_of_angles_are_those_of_the_named_geometries():
    """A curved panel's columns are geometries given by their angles, not names: the same
    angles, in and out of plane, broadcast over one lamp and many columns."""
    names = (*INSTRUMENT_GEOMETRIES["ma-t12"], "45as25az90", "45as25az-60")
    geometries = parse_geometries(names)
    angles = [[getattr(g, a) for g in geometries] for a in ("illumination", "aspecular", "azimuth")]
    np.testing.assert_allclose(flake_angles_at(*angles), flake_angles(names))
    np.testing.assert_allclose(directions_at(*angles), directions(names))
    sweep = flake_angles_at(15.0, [-45.0, -30.0, -15.0, 15.0, 45.0, 80.0], n=1.4)
    np.testing.assert_allclose(sweep, flake_angles(INSTRUMENT_GEOMETRIES["ma-t12"][:6], n=1.4))


def test_refraction_follows_snell_and_keeps_unit_length():
    rng = np.random.default_rng(2)
    theta, phi = rng.uniform(0, np.pi / 2 * 0.99, 100), rng.uniform(0, 2 * np.pi, 100)
    d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)
    inside = refract_into_coating(d, 1.5)
    np.testing.assert_allclose(np.linalg.norm(inside, axis=-1), 1)
    sin_inside = np.hypot(inside[:, 0], inside[:, 1])
    np.testing.assert_allclose(np.sin(theta), 1.5 * sin_inside)
    np.testing.assert_allclose(np.arctan2(inside[:, 1], inside[:, 0]), np.arctan2(d[:, 1], d[:, 0]))


def test_instrument_sets():
    assert len(instrument_geometries("MA-T12")) == 12
    assert [g.name for g in instrument_geometries("BYK-mac i")] == list(
        INSTRUMENT_GEOMETRIES["byk-mac-i"]
    )
    assert len(instrument_geometries("five-angle")) == 5
    with pytest.raises(ValueError, match="expected one of byk-mac-i"):
        instrument_geometries("ma-t99")


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("45 degrees", "expected a geometry name"),
        ("45as140", "expected a detector above"),
        ("95as15", "expected illumination angle"),
        ("", "expected a geometry name"),
        ("d/8", "a sphere's diffuse reading has no angle"),
        ("di:8°", "a sphere's diffuse reading has no angle"),
        ("45°:15°", "which side of the normal .* as 45as30 or 45as60, name it so"),
    ],
)
def test_bad_names_rejected_with_message(name, message):
    with pytest.raises(ValueError, match=message):
        Geometry.parse(name)


@pytest.mark.parametrize("name", ["45°:0°", "45:0", "45/0", " 45 ° / 0 ° "])
def test_the_cie_name_of_the_detector_along_the_normal_is_read(name):
    """CIE 15's 45°:0°, as an instrument for solid colours exports it, is 45as45: the
    detector along the normal, 45° from specular (refused before as no geometry name)."""
    geometry = Geometry.parse(name)
    assert geometry == Geometry.parse("45as45") and geometry.viewing == 0
