"""What a command, a comparison or a case uses where nothing names it: the illuminant and
observer of CIELAB, the tolerance a colour is judged against, and the colour difference at
which a film hides its primer.

They live here, apart from :mod:`flakelab.core.colorimetry` and :mod:`flakelab.core.tolerance`
where their meaning is defined, because this module imports nothing: the command line gives
them as option defaults at start-up without paying for colour-science's import (about a
second). The default instrument lives with the instrument sets,
:data:`flakelab.core.geometry.DEFAULT_INSTRUMENT`."""

DEFAULT_CONDITIONS = "D65/10"
"""CIELAB under D65 with the CIE 1964 10° observer (automotive practice; DESIGN §2), as
:meth:`flakelab.core.colorimetry.Conditions.parse` reads it."""

DEFAULT_TOLERANCE = "refinish"
"""flakelab's body-shop tolerance, one of :data:`flakelab.core.tolerance.TOLERANCE_PRESETS`."""

HIDING_DE00 = 1.0
"""ΔE00 between a film over black and over white (or over a grey and built up) at which it
hides, at every geometry: a colorimetric hiding criterion, as DIN 55987 reads hiding from the
colour difference of a film over black and over white (:mod:`flakelab.physics.hiding`)."""
