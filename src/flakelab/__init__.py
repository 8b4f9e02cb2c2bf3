"""flakelab: match, predict and show the appearance of car paints.

Layers (``../DESIGN.md`` §8), each a subpackage, arrows pointing down::

    cli                      thin: parse, call, present
    render                   images and plots
    io                       measurement files (MA-T12 xlsx, CxF3, CSV, JSON)
    core                     spectra, colour, geometry, measurement, tolerances
"""

from flakelab.errors import FlakelabError, MeasurementFileError

__version__ = "0.1.0"

__all__ = ["FlakelabError", "MeasurementFileError", "__version__"]
