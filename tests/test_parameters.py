"""The declarations in use: scenes, the sensor file, the sweep spec; their listings and the parameters page.

Each moved onto ``paramspec``: the listings (``salo scenes NAME``, ``salo sensors
--keys``, ``salo sweep --help``) and ``docs/parameters.md`` are made from the
declarations, and the old validators' behaviour holds (their own tests, in
test_scenes*.py, test_sensor.py and test_sweep_runner.py, keep passing).
"""

from __future__ import annotations

import pytest

import scenes
from paramspec import help_text, unit_of
from tools.cli import main


# ---------------------------------------------------------------- scenes
def test_scene_parameters_are_declared_with_help_and_units():
    for name in scenes.SCENES:
        sec = scenes.scene_schema(name)
        assert sec.name == name and sec.help == scenes.SCENES[name].DESCRIPTION
        for p in sec.members:
            assert p.help and not p.help.endswith((", m", ", m/s", ", deg", "percent")), (name, p.name)
            assert p.unit == unit_of(p.name), (name, p.name)
            assert p.type in ("bool", "int", "float", "str") and not p.nullable


def test_salo_scenes_lists_the_declarations(capsys):
    assert main(["scenes", "canyon"]) == 0
    out = capsys.readouterr().out
    assert help_text(scenes.scene_schema("canyon"), header=True) in out
    assert "tunnel_cross_section" in out and "arch|box" in out and "[-8, 8]" in out


def test_scene_errors_name_the_scene_and_key():
    cases = [
        ({"streets_x": 1}, "scene city: key 'streets_x' must be an integer in [2, 12], got 1"),
        ({"streets_x": "three"}, "scene city: key 'streets_x' must be an integer in [2, 12], got 'three'"),
        ({"speed": 3}, "scene city: key 'speed' is unknown; did you mean 'speed_m_s'?"),
        ({"closed_loop": "maybe"}, "scene city: key 'closed_loop' must be true or false, got 'maybe'"),
        ({"building_height_max_m": 5.0}, "scene city: key 'building_height_max_m' is below building_height_min_m"),
    ]
    for overrides, text in cases:
        with pytest.raises(ValueError) as err:  # a ParamError is a ValueError, as before
            scenes.resolve_params("city", **overrides)
        assert str(err.value).startswith(text)
    # the old coercions: text, integral floats, 0/1 for a bool; floats stored as floats
    p = scenes.resolve_params("city", streets_x="3", route_blocks=2.0, closed_loop=0, speed_m_s=9)
    assert (p.streets_x, p.route_blocks, p.closed_loop, p.speed_m_s) == (3, 2, False, 9.0)
    assert type(p.speed_m_s) is float
