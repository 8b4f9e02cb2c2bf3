"""flakelab: match, predict and show the appearance of car paints.

Layers (DESIGN.md §8), each a subpackage, arrows pointing down but for two: the case
generator (``cases.generator``) makes its cases with the physics and the texture readings'
model, and ``io`` reads library and tin files into the library's types
(``tests/test_layers.py``). The README's Layout says what each holds::

    cli                          thin: parse, call, present
    match, render                the two jobs: recipes and their correction; images, plots
    models, physics, texture     learned forward model; coating optics; sparkle, graininess
    cases, library               refinish cases and their database; toners and tins
    io                           measurement, library, recipe and tolerance files
    core                         spectra, colour, geometry, measurement, tolerances
"""

from flakelab.errors import FlakelabError, MeasurementFileError

__version__ = "0.1.0"

__all__ = ["FlakelabError", "MeasurementFileError", "__version__"]
