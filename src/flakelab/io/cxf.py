"""CxF3 (ISO 17972-1) with multi-angle geometry, through colour-cxf.

Layout written (and expected on reading):

- one ``ColorSpecification`` per geometry, ``Id="CS_<name>"``, whose ``MeasurementSpec``
  holds ``GeometryChoice/MultiAngle/BRDFAngle`` (IlluminationAngle, Aspecular, Azimuth,
  ``Notation`` = the ASTM name) and the ``WavelengthRange``;
- one ``Object`` per sample, with a ``ReflectanceSpectrum`` (and optionally a
  ``ColorCIELab``) per geometry referring to that specification;
- read too: an Object that gives a colour per geometry and no spectra (``ColorCIELab``, or
  ``ColorCIELCh`` or ``ColorCIEXYZ`` [Y 0–100] as some instruments export it, taken to
  L*a*b* under its ColorSpecification's conditions by colour-science), its spectra
  recovered from that colour;
- texture readings, instrument and free metadata as ``Tag`` elements in a ``TagCollection``
  named ``flakelab`` (``texture:Sa15``, ``instrument``, ``meta:<key>``);
- a QC job's standard as the one Object of ``ObjectType="Standard"`` among its trials
  (:data:`STANDARD_TYPE`), read as the standard the file names.
"""

from __future__ import annotations

import logging
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import datetime
from os import PathLike
from pathlib import Path

import colour_cxf
import numpy as np
from colour_cxf import cxf3
from xsdata.exceptions import ConverterWarning, ParserError
from xsdata.logger import logger as xsdata_logger
from xsdata.models.datatype import XmlDateTime

from flakelab import __version__
from flakelab.core.colorimetry import D65_10, Conditions
from flakelab.core.geometry import Geometry
from flakelab.core.measurement import Measurement
from flakelab.core.spectra import WAVELENGTHS
from flakelab.errors import MeasurementFileError, Note
from flakelab.io.records import (
    UTF16_BOMS,
    Reading,
    agreed_colour,
    assemble,
    checked_wavelengths,
    parse_colour,
    parse_conditions,
    parse_number,
    parse_spectrum,
    parse_texture,
    recovered_readings,
    standard_of,
    utf8_of_utf16,
    write_atomically,
)

__all__ = ["read_cxf", "write_cxf"]

_TAGS = "flakelab"
_CXF_ILLUMINANTS = {m.value for m in cxf3.EilluminantType}


def _geometry_of(path: str | PathLike, spec: cxf3.ColorSpecification) -> Geometry | None:
    choice = spec.measurement_spec.geometry_choice if spec.measurement_spec else None
    multi = getattr(choice, "choice", None)
    if not isinstance(multi, cxf3.MultiAngleType):
        return None
    if len(multi.brdfangle) != 1:
        raise MeasurementFileError(
            path,
            f"expected one BRDFAngle, got {len(multi.brdfangle)}",
            field=f"ColorSpecification {spec.id}",
        )
    angle = multi.brdfangle[0]
    where = f"ColorSpecification {spec.id}, BRDFAngle"
    try:
        geometry = Geometry(
            parse_number(path, angle.illumination_angle, f"{where}, IlluminationAngle"),
            parse_number(path, angle.aspecular, f"{where}, Aspecular"),
            0.0
            if angle.azimuth is None
            else parse_number(path, angle.azimuth, f"{where}, Azimuth"),
        )
    except ValueError as error:
        if isinstance(error, MeasurementFileError):
            raise
        raise MeasurementFileError(path, str(error), field=where) from None
    if angle.notation and _parses(angle.notation) and Geometry.parse(angle.notation) != geometry:
        raise MeasurementFileError(
            path,
            f"Notation {angle.notation!r} disagrees with the angles ({geometry.name})",
            field=where,
        )
    return geometry


def _parses(name: str) -> bool:
    try:
        Geometry.parse(name)
    except ValueError:
        return False
    return True


def _conditions_of(path: str | PathLike, spec: cxf3.ColorSpecification) -> Conditions | None:
    tristimulus = spec.tristimulus_spec
    if tristimulus is None or tristimulus.observer is None:
        return None
    illuminant = tristimulus.illuminant_or_custom_illuminant
    name = getattr(getattr(illuminant, "value", None), "value", None)
    observer = getattr(tristimulus.observer.value, "value", "")
    if name is None:
        return None
    return parse_conditions(
        path, f"{name}/{observer.split('_')[0]}", f"ColorSpecification {spec.id}, TristimulusSpec"
    )


@contextmanager
def _parser_log() -> Iterator[list[str]]:
    """What xsdata logs while it parses (an element or text it read where the schema has no
    place for it), kept to be said as notes naming the file: its logger would print it on
    stderr as a bare line that names no file ("Unassigned parsed object None")."""
    said: list[str] = []
    handler = logging.Handler()
    handler.emit = lambda record: said.append(record.getMessage())  # type: ignore[method-assign]
    xsdata_logger.addHandler(handler)
    propagates, xsdata_logger.propagate = xsdata_logger.propagate, False
    try:
        yield said
    finally:
        xsdata_logger.removeHandler(handler)
        xsdata_logger.propagate = propagates


def read_cxf(path: str | PathLike, content: bytes | None = None) -> list[Measurement]:
    """Read multi-angle reflectance measurements from a CxF3 file."""
    data = Path(path).read_bytes() if content is None else content
    if data.startswith(UTF16_BOMS):
        try:
            data = utf8_of_utf16(data)
        except UnicodeDecodeError as error:
            raise MeasurementFileError(path, f"not UTF-16 text ({error.reason})") from None
    try:
        # a value xsdata cannot convert stays text and is named below, by field and wavelength
        with warnings.catch_warnings(), _parser_log() as skipped:
            warnings.simplefilter("ignore", ConverterWarning)
            document = colour_cxf.read_cxf(data)
    # LookupError: an XML declaration naming an encoding Python does not know
    except (ParserError, ValueError, TypeError, LookupError) as error:
        raise MeasurementFileError(path, f"not valid CxF3 XML ({error})") from None
    for said in dict.fromkeys(skipped):
        warnings.warn(
            f"{path}: part of the XML has no place in CxF3's schema and was skipped ({said})",
            Note,
            stacklevel=2,
        )
    resources = document.resources
    specs = (
        resources.color_specification_collection.color_specification
        if resources and resources.color_specification_collection
        else []
    )
    geometries = {s.id: _geometry_of(path, s) for s in specs}
    conditions = {s.id: _conditions_of(path, s) for s in specs}
    objects = (
        resources.object_collection.object_value
        if resources and resources.object_collection
        else []
    )
    if not objects:
        raise MeasurementFileError(path, "no Object in ObjectCollection")

    readings, lab_alone, texture, metadata = [], [], {}, {}
    wavelengths: np.ndarray | None = None
    instrument = None
    lab_conditions = D65_10
    for obj in objects:
        sample = obj.name or obj.id
        values = obj.color_values.choice if obj.color_values else []
        labs = _colours_of(path, sample, values, conditions)
        measured_at = _creation_date(path, sample, obj.creation_date)
        spectral = {
            v.color_specification for v in values if isinstance(v, cxf3.ReflectanceSpectrum)
        }
        lab_alone += [
            Reading(f"Object {sample!r}, {kind} {spec}", sample, geometries.get(spec), None, lab,
                    measured_at, {"spec": spec})
            for spec, (kind, lab) in labs.items() if spec not in spectral
        ]  # fmt: skip
        for v in values:
            if not isinstance(v, cxf3.ReflectanceSpectrum):
                continue
            where = f"Object {sample!r}, ReflectanceSpectrum {v.color_specification}"
            geometry = geometries.get(v.color_specification)
            if geometry is None:
                raise MeasurementFileError(
                    path, "its ColorSpecification has no MultiAngle BRDFAngle geometry", field=where
                )
            spec = next(s for s in specs if s.id == v.color_specification)
            wr = spec.measurement_spec.wavelength_range
            start = v.start_wl if v.start_wl is not None else (wr.start_wl if wr else None)
            if start is None or wr is None or wr.increment is None:
                raise MeasurementFileError(
                    path, "no StartWL or WavelengthRange Increment", field=where
                )
            start = parse_number(path, start, f"{where}, StartWL")
            increment = parse_number(
                path, wr.increment, f"ColorSpecification {spec.id}, WavelengthRange Increment"
            )
            # a spectrum with a value that is not a number comes as the element's text
            spectrum = v.value.split() if isinstance(v.value, str) else v.value
            grid = start + increment * np.arange(len(spectrum), dtype=float)
            if wavelengths is None:
                wavelengths = checked_wavelengths(path, grid, where)
            elif not np.array_equal(grid, wavelengths):
                raise MeasurementFileError(
                    path, "spectra on different wavelength grids", field=where
                )
            lab = labs.get(v.color_specification, (None, None))[1]
            if lab is not None and conditions.get(v.color_specification):
                lab_conditions = conditions[v.color_specification]
            readings.append(
                Reading(
                    where=where,
                    sample=sample,
                    geometry=geometry,
                    reflectance=parse_spectrum(path, spectrum, grid, where),
                    lab=lab,
                    measured_at=measured_at,
                )
            )
        for collection in obj.tag_collection:
            if collection.name != _TAGS:
                continue
            for tag in collection.tag:
                key, value = tag.name or "", tag.value or ""
                if key.startswith("texture:"):
                    texture.setdefault(sample, {})[key[8:]] = parse_texture(
                        path, value, f"Object {sample!r}, Tag {key}"
                    )
                elif key == "instrument":
                    instrument = value
                elif key.startswith("meta:"):
                    metadata.setdefault(sample, {})[key[5:]] = value
    if wavelengths is None and not lab_alone:
        raise MeasurementFileError(
            path, f"no ReflectanceSpectrum or {', '.join(COLOUR_VALUES)} in any Object"
        )
    _check_one_kind_per_sample(path, readings, lab_alone)
    if (standard := _standard_marked(objects)) is not None:
        for obj in objects:
            metadata.setdefault(obj.name or obj.id, {}).setdefault("standard", standard)
    keep = dict(instrument=instrument, texture=texture, metadata=metadata)
    measured = []
    if readings:
        measured = assemble(path, readings, wavelengths, lab_conditions=lab_conditions, **keep)
    if not lab_alone:
        return measured
    # Objects of a colour alone (some software stores a standard so beside measured
    # trials): their spectra recovered from it (one metamer of many), each flagged so
    recovered, grid, lab_conditions = _recovered(path, lab_alone, conditions)
    by_colour = assemble(path, recovered, grid, lab_conditions=lab_conditions,
                         spectra_recovered=True, **keep)  # fmt: skip
    order = {name: i for i, name in enumerate(obj.name or obj.id for obj in objects)}
    return sorted(measured + by_colour, key=lambda m: order[m.sample])


STANDARD_TYPE = "Standard"
"""The ObjectType of a QC job's standard: the one Object a document of several marks so is
the standard its others (``Trial``, ``Sample`` …) are judged against; written for the standard
a file names (:func:`~flakelab.io.records.standard_of`), or a document's one Object."""


def _standard_marked(objects: list[cxf3.Object]) -> str | None:
    """The name of the one Object of several whose ObjectType is :data:`STANDARD_TYPE`;
    None where a document marks none or several (a library of standards)."""
    marked = [o for o in objects if (o.object_type or "").strip().lower() == "standard"]
    if len(objects) < 2 or len(marked) != 1:
        return None
    return marked[0].name or marked[0].id


def _object_type(m: Measurement, standard: Measurement | None, alone: bool) -> str:
    """The ObjectType written for ``m``: the file's ``standard`` (or its one Object) a
    :data:`STANDARD_TYPE`, the others then ``Trial``, else ``Sample``."""
    if alone or m is standard:
        return STANDARD_TYPE
    return "Trial" if standard is not None else "Sample"


def _check_one_kind_per_sample(
    path: str | PathLike, measured: list[Reading], lab_alone: list[Reading]
) -> None:
    """A sample is measured (its spectra) or known by its colour alone at every geometry: a
    geometry of ColorCIELab alone in a sample whose other geometries give spectra is refused,
    by name, where it was left out unsaid."""
    samples = {r.sample for r in measured}
    if mixed := next((r for r in lab_alone if r.sample in samples), None):
        raise MeasurementFileError(
            path,
            "a colour without a ReflectanceSpectrum, where the sample's other geometries "
            "give spectra: a measurement is read from its spectra or from its colour alone, "
            "not both",
            field=mixed.where,
        )


def _recovered(
    path: str | PathLike, readings: list[Reading], conditions: dict[str, Conditions | None]
) -> tuple[list[Reading], np.ndarray, Conditions]:
    """Readings of a file that gives ColorCIELab alone, each with a spectrum recovered from
    its colour (:func:`~flakelab.io.records.recovered_readings`); their geometries and the
    one set of conditions their ColorSpecifications name (D65/10 where none)."""
    for reading in readings:
        if reading.geometry is None:
            raise MeasurementFileError(
                path, "its ColorSpecification has no MultiAngle BRDFAngle geometry",
                field=reading.where,
            )  # fmt: skip
    named = {conditions.get(r.extras["spec"]) or D65_10 for r in readings}
    if len(named) > 1:
        raise MeasurementFileError(
            path, f"colours alone under several conditions: {sorted(map(str, named))}"
        )
    lab_conditions = named.pop()
    return recovered_readings(path, readings, lab_conditions), WAVELENGTHS, lab_conditions


COLOUR_VALUES = {
    "ColorCIELab": cxf3.ColorCielab,
    "ColorCIELCh": cxf3.ColorCielch,
    "ColorCIEXYZ": cxf3.ColorCiexyz,
}
"""The colours an Object may give per geometry in place of a spectrum, each read as L*a*b*,
by their CxF3 names, in the order taken where one geometry gives several."""


def _colours_of(
    path: str | PathLike, sample: str, values: list, conditions: dict[str, Conditions | None]
) -> dict[str, tuple[str, np.ndarray]]:
    """An Object's stored colour per ColorSpecification, as its kind and L*a*b* under the
    specification's conditions (D65/10 where it names none): ColorCIELab as given,
    ColorCIELCh and ColorCIEXYZ [Y 0–100] converted by colour-science; where a geometry
    gives several, the first of :data:`COLOUR_VALUES`, the others agreeing with it
    (:func:`~flakelab.io.records.agreed_colour`)."""
    stated: dict[str, dict[str, np.ndarray]] = {}
    for kind, cls in COLOUR_VALUES.items():
        for v in values:
            spec = v.color_specification
            if isinstance(v, cls) and kind not in stated.setdefault(spec, {}):
                where = f"Object {sample!r}, {kind} {spec}"
                stated[spec][kind] = _as_lab(path, where, v, conditions.get(spec) or D65_10)
    return {
        spec: (next(iter(forms)), agreed_colour(path, forms, f"Object {sample!r}, {spec}"))
        for spec, forms in stated.items()
        if forms
    }


def _as_lab(path: str | PathLike, where: str, value, conditions: Conditions) -> np.ndarray:
    """One stored colour as L*a*b* ``[3]`` under ``conditions``, each cell checked and
    named."""
    if isinstance(value, cxf3.ColorCielab):
        form, cells, names = "Lab", (value.l, value.a, value.b), "LAB"
    elif isinstance(value, cxf3.ColorCielch):
        form, cells, names = "LCh", (value.l, value.c, value.h), "LCH"
    else:
        form, cells, names = "XYZ", (value.x, value.y, value.z), "XYZ"
    return parse_colour(path, form, cells, where, names, conditions)


def _creation_date(
    path: str | PathLike, sample: str, date: cxf3.CreationDate | None
) -> datetime | None:
    """An Object's CreationDate; xsdata leaves one it cannot read as text."""
    if date is None or date.value is None:
        return None
    if not isinstance(date.value, XmlDateTime):
        raise MeasurementFileError(
            path,
            f"expected an xs:dateTime, got {date.value!r}",
            field=f"Object {sample!r}, CreationDate",
        )
    return date.value.to_datetime()


def _xml_datetime(moment: datetime | None) -> cxf3.CreationDate:
    moment = moment or datetime.now().replace(microsecond=0)
    return cxf3.CreationDate(value=XmlDateTime.from_datetime(moment))


def _specification(geometry: Geometry, wavelengths: np.ndarray, conditions: Conditions):
    interval = int(round(wavelengths[1] - wavelengths[0]))
    cxf_illuminant = conditions.illuminant.replace("FL", "F")
    tristimulus = None
    if cxf_illuminant in _CXF_ILLUMINANTS:
        tristimulus = cxf3.TristimulusSpec(
            illuminant_or_custom_illuminant=cxf3.Illuminant(
                value=cxf3.EilluminantType(cxf_illuminant)
            ),
            observer=cxf3.Observer(value=cxf3.EobserverType(f"{conditions.observer}_Degree")),
            method=cxf3.Method(value=cxf3.EastmTableType.E308_TABLE6),
        )
    return cxf3.ColorSpecification(
        id=f"CS_{geometry.name}",
        tristimulus_spec=tristimulus,
        measurement_spec=cxf3.MeasurementSpec(
            measurement_type=cxf3.MeasurementType(value=cxf3.EspectrumType.SPECTRUM_REFLECTANCE),
            geometry_choice=cxf3.GeometryChoice(
                choice=cxf3.MultiAngleType(
                    brdfangle=[
                        cxf3.Brdfangle(
                            illumination_angle=geometry.illumination,
                            aspecular=geometry.aspecular,
                            azimuth=None if geometry.in_plane else geometry.azimuth,
                            notation=geometry.name,
                        )
                    ]
                )
            ),
            wavelength_range=cxf3.WavelengthRange(start_wl=int(wavelengths[0]), increment=interval),
        ),
    )


def write_cxf(measurements: list[Measurement], path: str | PathLike) -> None:
    """Write measurements as one CxF3 document (see module docstring for the layout); those
    whose spectra were recovered from L*a*b* as ColorCIELab alone, as they were read, beside
    measured ones where the document holds both (a standard's colour and a trial)."""
    wavelengths = measurements[0].wavelengths
    if not 360 <= wavelengths[0] <= 400 or np.any(np.diff(wavelengths) % 1):
        raise ValueError(
            f"CxF3 holds spectra starting at 360–400 nm on whole-nm steps, got start "
            f"{wavelengths[0]:g} nm"
        )
    geometries = sorted({g for m in measurements for g in m.geometries})
    conditions = measurements[0].stored_lab_conditions
    specs = [_specification(g, wavelengths, conditions) for g in geometries]
    objects, standard = [], standard_of(measurements)
    for number, m in enumerate(measurements, start=1):
        values: list[object] = []
        for i, g in enumerate(m.geometries):
            if not m.spectra_recovered:
                values.append(
                    cxf3.ReflectanceSpectrum(
                        value=[float(v) for v in m.reflectance[i]],
                        start_wl=int(m.wavelengths[0]),
                        color_specification=f"CS_{g.name}",
                    )
                )
            if m.stored_lab is not None:
                L, a, b = map(float, m.stored_lab[i])
                values.append(cxf3.ColorCielab(l=L, a=a, b=b, color_specification=f"CS_{g.name}"))
        tags = [cxf3.Tag(name=f"texture:{k}", value=repr(v)) for k, v in m.texture.items()]
        tags += [cxf3.Tag(name=f"meta:{k}", value=v) for k, v in m.metadata.items()]
        if m.instrument:
            tags.append(cxf3.Tag(name="instrument", value=m.instrument))
        objects.append(
            cxf3.Object(
                object_type=_object_type(m, standard, len(measurements) == 1),
                name=m.sample,
                id=str(number),
                creation_date=_xml_datetime(m.measured_at),
                color_values=cxf3.ColorValues(choice=values),
                tag_collection=[cxf3.TagCollection(name=_TAGS, tag=tags)] if tags else [],
            )
        )
    document = cxf3.CxF(
        file_information=cxf3.FileInformation(
            creator=f"flakelab {__version__}",
            creation_date=_xml_datetime(None),
            description="Multi-angle reflectance measurements",
        ),
        resources=cxf3.Resources(
            object_collection=cxf3.ObjectCollection(object_value=objects),
            color_specification_collection=cxf3.ColorSpecificationCollection(
                color_specification=specs
            ),
        ),
    )
    data = colour_cxf.write_cxf(document)
    write_atomically(path, lambda temporary: temporary.write_bytes(data))
