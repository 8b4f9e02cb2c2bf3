"""How reports count things (flakelab.core.wording)."""

from flakelab.core.wording import counted


def test_one_thing_is_singular_and_any_other_count_plural():
    assert counted(1, "case") == "1 case"
    assert counted(0, "case") == "0 cases"
    assert counted(2, "spray-out") == "2 spray-outs"
    assert counted(1, "geometry", "geometries") == "1 geometry"
    assert counted(5, "geometry", "geometries") == "5 geometries"
