"""How a report counts things: "1 case", "3 cases". One place, so that no message reads
"1 cases" or hedges with "case(s)". It imports nothing, like :mod:`flakelab.core.defaults`."""


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and ``noun``, the noun plural unless ``n`` is 1: ``counted(1, "case")`` is
    "1 case", ``counted(2, "spray-out")`` "2 spray-outs"; ``plural`` where adding an "s"
    does not make it ("geometry", "geometries")."""
    return f"{n} {noun if n == 1 else plural or noun + 's'}"
