"""sweeps.axes: grid axes from text (directions, phases, impulses) and their refusals."""

import pytest

from sweeps.axes import DIRECTIONS_RAD, GridError, direction_rad, parse_directions, parse_impulses, parse_phases


@pytest.mark.parametrize("text, expected", [
    ("4", (0.0, 0.25, 0.5, 0.75)), ("0,0.5", (0.0, 0.5)), ("0.3", (0.3,)),
])
def test_parse_phases(text, expected):
    assert parse_phases(text) == pytest.approx(expected)


@pytest.mark.parametrize("text, expected", [("0:10:3", (0.0, 5.0, 10.0)), ("1,2.5", (1.0, 2.5)), ("3", (3.0,))])
def test_parse_impulses(text, expected):
    assert parse_impulses(text) == pytest.approx(expected)


@pytest.mark.parametrize("parse, text, match", [
    (parse_phases, "0", "count >= 1"), (parse_phases, "", "empty|count"), (parse_phases, "0.2,1.0", r"\[0, 1\)"),
    (parse_impulses, "0:10:0", "empty grid"), (parse_impulses, "-1,2", "non-negative"),
    (parse_impulses, "1,inf", "finite"), (parse_impulses, "1:2", "start:stop:num"), (parse_impulses, "a", "N s"),
    (parse_directions, "0", r"\[1, 360\]"), (parse_directions, ",", "no direction"), (parse_directions, "up", "'up'"),
    (parse_directions, "forward,360", "heading twice"), (parse_directions, "left,nan", "'nan'"),
])
def test_bad_grids_name_the_problem(parse, text, match):
    with pytest.raises(GridError, match=match):
        parse(text)


def test_directions_are_names_or_degrees_from_forward():
    assert parse_directions("8") == ("0", "45", "90", "135", "180", "225", "270", "315")
    assert parse_directions("forward, 45.0,left") == ("forward", "45", "left")
    assert direction_rad("90") == pytest.approx(DIRECTIONS_RAD["left"])
    assert direction_rad("-90") == pytest.approx(DIRECTIONS_RAD["right"])
