"""The declarative parameter mechanism (paramspec): declaring, reading, every error, help text, Markdown.

A synthetic ``Demo`` declaration, with a nested section as an odometry config
grouped by stage would have, exercises it; ``test_parameters.py`` checks the
declarations in use (scenes, the sensor file, the sweep spec).
"""

from __future__ import annotations

import pickle
from dataclasses import dataclass

import pytest

from paramspec import (
    REQUIRED,
    Param,
    ParamError,
    Params,
    Section,
    assignments,
    differences,
    help_text,
    markdown,
    param,
    schema,
    section,
    unit_of,
)


class DemoError(ParamError):
    """A section's own error class (as SensorError, SpecError)."""


@dataclass(frozen=True)
class Stage(Params):
    """A nested stage."""

    section_name = "stage"
    enabled: bool = param(True, "run the stage")
    max_normal_std_deg: float = param(5.0, "largest std of a kept normal", above=0.0)
    model: str = param("range", "noise model", choices=("range", "isotropic"))


@dataclass(frozen=True)
class Demo(Params):
    """A demo set of parameters."""

    section_name = "demo"
    name: str = param(help="a required name", check=lambda s: None if s else "must be a non-empty string")
    frames: int = param(100, "sweeps per sequence", min=2, max=1000)
    speed_m_s: float | None = param(None, "cruise speed (null: the scene's own)", above=0.0)
    ratio: float = param(0.5, "a fraction", min=0.0, below=1.0, unit="")
    seeds: tuple[int, ...] = param((0,), "seeds", min=0, one_or_more=True, unique=True)
    angles_deg: tuple[float, ...] = param((1.0, 2.0), "angles", above=-90.0, below=90.0)
    extra: dict = param({}, "free-form overrides")
    stage: Stage = section(Stage, "the stage")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.speed_m_s is not None and self.frames > 10 * self.speed_m_s:
            raise ParamError(f"is {self.frames}: more than 10 x speed_m_s", "frames")


def error(fn, *args, **kwargs) -> str:
    with pytest.raises(ParamError) as err:
        fn(*args, **kwargs)
    assert "\n" not in str(err.value)  # one line
    return str(err.value)


# ---------------------------------------------------------------- declarations
def test_schema_reads_types_units_defaults_and_nesting():
    s = schema(Demo)
    assert s.name == "demo" and s.help == "A demo set of parameters." and s.cls is Demo
    assert s.names == ("name", "frames", "speed_m_s", "ratio", "seeds", "angles_deg", "extra", "stage")
    assert s["name"].required and s["name"].default is REQUIRED and not s["frames"].required
    assert (s["frames"].type, s["frames"].min, s["frames"].max, s["frames"].unit) == ("int", 2, 1000, "")
    assert (s["speed_m_s"].type, s["speed_m_s"].nullable, s["speed_m_s"].unit) == ("float", True, "m/s")
    assert s["ratio"].unit == ""  # declared: overrides the name
    assert (s["seeds"].type, s["angles_deg"].type, s["angles_deg"].unit, s["extra"].type) == (
        "list[int]", "list[float]", "deg", "mapping")
    assert isinstance(s["stage"], Section) and s["stage"].help == "the stage"
    assert [n for n, _ in s.walk()][-4:] == ["stage", "stage.enabled", "stage.max_normal_std_deg", "stage.model"]


def test_units_follow_the_names():
    assert [unit_of(n) for n in ("speed_m_s", "accel_m_s2", "length_m", "start_s", "grade_pct", "rotation_hz",
                                 "azimuth_step_deg", "trees_per_ha", "houses_per_100m", "frames", "rocks")] == [
        "m/s", "m/s^2", "m", "s", "%", "Hz", "deg", "1/ha", "1/100 m", "", ""]


def test_bad_declarations_are_refused():
    with pytest.raises(TypeError, match="declare it with param"):
        @dataclass(frozen=True)
        class Undeclared(Params):
            x: int = 3

        schema(Undeclared)
    with pytest.raises(TypeError, match="not a parameter type"):
        @dataclass(frozen=True)
        class Odd(Params):
            x: set = param(frozenset(), "a set")

        schema(Odd)
    with pytest.raises(TypeError, match="unknown type"):
        Param("x", "complex")


# ---------------------------------------------------------------- reading
def test_defaults_round_trip_and_overlay_on_a_base():
    d = Demo(name="a")
    assert d.stage == Stage() and d.seeds == (0,) and d.extra == {}
    assert Demo.from_dict(d.to_dict()) == d
    e = Demo.from_dict({"name": "b", "frames": 7, "speed_m_s": 1, "seeds": 3, "stage": {"enabled": False}})
    assert (e.frames, e.speed_m_s, e.seeds, e.stage.enabled, e.stage.model) == (7, 1, (3,), False, "range")
    assert Demo.from_dict(e.to_dict()) == e
    # keys left out keep the base's values, a section's too
    f = Demo.from_dict({"stage": {"model": "isotropic"}}, base=e)
    assert (f.name, f.frames, f.stage.enabled, f.stage.model) == ("b", 7, False, "isotropic")
    assert Demo(name="c", stage={"enabled": False}).stage == Stage(enabled=False)  # a section as a dict
    assert Demo(name="c", angles_deg=[3, 4]).angles_deg == (3, 4)  # lists become tuples
    assert Demo.from_dict({"name": "x", "extra": None, "stage": None}) == Demo(name="x")  # empty YAML sections


def test_strict_values_keep_their_type_and_coerced_text_is_converted():
    d = Demo.from_dict({"name": "a", "speed_m_s": 20})
    assert d.speed_m_s == 20 and type(d.speed_m_s) is int  # strict: a number stays as given (hashes unchanged)
    c = Demo.from_dict({"name": "a", "frames": "30", "speed_m_s": "20", "seeds": "1, 2",
                        "stage": {"enabled": "no", "max_normal_std_deg": "3"}}, coerce=True)
    assert (c.frames, c.speed_m_s, c.seeds, c.stage.enabled, c.stage.max_normal_std_deg) == (30, 20.0, (1, 2), False,
                                                                                            3.0)
    assert type(c.speed_m_s) is float
    assert Demo.from_dict({"name": "a", "frames": 40.0, "stage": {"enabled": 1}}, coerce=True).frames == 40
    for text, value in (("yes", True), ("on", True), ("1", True), ("false", False), ("off", False), ("0", False)):
        assert Demo.from_dict({"name": "a", "stage": {"enabled": text}}, coerce=True).stage.enabled is value
    assert "got 'yes'" in error(Demo.from_dict, {"name": "a", "stage": {"enabled": "yes"}})  # strict: not text


def test_assignments_nest_dotted_keys():
    pairs = ["frames=30", " stage.enabled = no", "stage.model=isotropic", "name=x=y"]
    assert assignments(pairs) == {"frames": "30", "stage": {"enabled": "no", "model": "isotropic"}, "name": "x=y"}
    d = Demo.from_dict(assignments(pairs), "--set", coerce=True)
    assert (d.frames, d.stage.enabled, d.stage.model, d.name) == (30, False, "isotropic", "x=y")
    assert error(assignments, ["frames"]) == "--set 'frames': expected KEY=VALUE"
    assert error(assignments, ["=3"], what="override") == "override '=3': expected KEY=VALUE"
    assert "expected KEY=VALUE" in error(assignments, ["stage.=3"])
    assert "frames is a key, not a section" in error(assignments, ["frames=1", "frames.x=2"])


def test_a_key_moved_into_a_section_is_named_with_its_new_dotted_key():
    """Keys of an older, flat layout: the key of the same name in a section, or the section's name + '_' + key."""
    cases = [
        ({"max_normal_std_deg": 3}, "key 'max_normal_std_deg' is unknown; did you mean 'stage.max_normal_std_deg'?"),
        ({"stage_model": "range"}, "key 'stage_model' is unknown; did you mean 'stage.model'?"),
        ({"stage_max_normal_std_deg": 3}, "key 'stage_max_normal_std_deg' is unknown; did you mean "
                                          "'stage.max_normal_std_deg'?"),
        ({"stage": False}, "key 'stage' must be a mapping of stage keys, got bool; did you mean 'stage.enabled'?"),
        ({"stage": "no"}, "key 'stage' must be a mapping of stage keys, got str; did you mean 'stage.enabled'?"),
    ]
    for data, text in cases:
        assert error(Demo.from_dict, {"name": "a", **data}, "--set", coerce=True) == f"--set: {text}"
    assert error(Demo.from_dict, {"stage": {"stage": 1}}, base=Demo(name="a")).startswith(
        "key 'stage.stage' is unknown (known: enabled,")  # the hint looks below the section, not above


def test_differences_name_the_changed_keys_dotted():
    a = Demo(name="a")
    b = Demo.from_dict({"frames": 7, "stage": {"model": "isotropic"}}, base=a)
    assert differences(b, a) == {"frames": 7, "stage.model": "isotropic"} and differences(a, a) == {}


def test_null_is_a_value_in_command_line_text_where_the_key_allows_it():
    assert Demo.from_dict(assignments(["speed_m_s=null"]), coerce=True, base=Demo(name="a", speed_m_s=30)).speed_m_s \
        is None
    assert error(Demo.from_dict, {"name": "a", "frames": "null"}, coerce=True) == (
        "key 'frames' must be an integer in [2, 1000], got 'null'")


# ---------------------------------------------------------------- every error path
@pytest.mark.parametrize(
    ("data", "text"),
    [
        # unknown keys, with the closest name: a forgotten unit suffix first, then the closest spelling
        ({"name": "a", "speed": 3}, "d.yaml: key 'speed' is unknown; did you mean 'speed_m_s'? (known: name, frames,"),
        ({"name": "a", "frame": 3}, "d.yaml: key 'frame' is unknown; did you mean 'frames'?"),
        ({"name": "a", "colour": 3}, "d.yaml: key 'colour' is unknown (known: name, frames, speed_m_s, ratio, seeds,"),
        ({"name": "a", "stage": {"enable": 1}}, "d.yaml: key 'stage.enable' is unknown; did you mean "
                                                "'stage.enabled'? "
                                                "(known: enabled, max_normal_std_deg, model)"),
        # missing, wrong type, null where not allowed
        ({}, "d.yaml: key 'name' is missing (a required name)"),
        ({"name": 3}, "d.yaml: key 'name' must be a string, got 3"),
        ({"name": ""}, "d.yaml: key 'name' must be a non-empty string"),  # the key's own check
        ({"name": "a", "frames": "many"}, "d.yaml: key 'frames' must be an integer in [2, 1000], got 'many'"),
        ({"name": "a", "frames": 2.5}, "d.yaml: key 'frames' must be an integer in [2, 1000], got 2.5"),
        ({"name": "a", "frames": True}, "d.yaml: key 'frames' must be an integer in [2, 1000], got true"),
        ({"name": "a", "frames": None}, "d.yaml: key 'frames' must be an integer in [2, 1000], got null"),
        ({"name": "a", "stage": {"enabled": None}}, "d.yaml: key 'stage.enabled' must be true or false, got null"),
        ({"name": "a", "extra": [1]}, "d.yaml: key 'extra' must be a mapping of names to values, got list"),
        ({"name": "a", "stage": 3}, "d.yaml: key 'stage' must be a mapping of stage keys, got int"),
        # out of range: inclusive and exclusive bounds, non-finite numbers
        ({"name": "a", "frames": 1}, "d.yaml: key 'frames' must be an integer in [2, 1000], got 1"),
        ({"name": "a", "frames": 1001}, "d.yaml: key 'frames' must be an integer in [2, 1000], got 1001"),
        ({"name": "a", "speed_m_s": 0}, "d.yaml: key 'speed_m_s' must be a number > 0 (m/s) or null, got 0"),
        ({"name": "a", "ratio": 1.0}, "d.yaml: key 'ratio' must be a number in [0, 1), got 1.0"),
        ({"name": "a", "ratio": float("nan")}, "d.yaml: key 'ratio' must be a number in [0, 1), got nan"),
        ({"name": "a", "stage": {"max_normal_std_deg": float("inf")}},
         "d.yaml: key 'stage.max_normal_std_deg' must be a number > 0 (deg), got inf"),
        # bad choice
        ({"name": "a", "stage": {"model": "round"}},
         "d.yaml: key 'stage.model' must be one of range, isotropic, got 'round'"),
        # lists: an entry out of range, twice, empty, not a list
        ({"name": "a", "seeds": [0, -1]}, "d.yaml: key 'seeds' has -1, which is not an integer >= 0"),
        ({"name": "a", "seeds": [1, 1]}, "d.yaml: key 'seeds' lists 1 twice"),
        ({"name": "a", "seeds": []}, "d.yaml: key 'seeds' is empty (leave the key out for its default)"),
        ({"name": "a", "angles_deg": 3.0}, "d.yaml: key 'angles_deg' must be a list of numbers in (-90, 90) (deg), "
                                           "got 3.0"),
        ({"name": "a", "angles_deg": [1, 90]}, "d.yaml: key 'angles_deg' has 90, which is not a number in (-90, 90)"),
        # a rule between keys, from __post_init__
        ({"name": "a", "speed_m_s": 1, "frames": 11}, "d.yaml: key 'frames' is 11: more than 10 x speed_m_s"),
    ],
)
def test_every_error_is_one_line_naming_origin_key_and_problem(data, text):
    assert error(Demo.from_dict, data, "d.yaml").startswith(text)


def test_errors_outside_a_file_and_as_another_class():
    assert error(Demo, name="a", frames=1) == "key 'frames' must be an integer in [2, 1000], got 1"
    assert error(Demo, name="a", stage=Stage(), seeds=(-1,)) == "key 'seeds' has -1, which is not an integer >= 0"
    assert error(Demo, name="a", stage={"model": "x"}) == "key 'stage.model' must be one of range, isotropic, got 'x'"
    assert error(Demo, name="a", stage=3) == ("key 'stage' must be a mapping of stage keys, got int; "
                                              "did you mean 'stage.enabled'?")
    assert error(Demo.from_dict, [1], "d.yaml") == "d.yaml: expected a mapping of demo keys, got list"
    e = ParamError("must be > 0", "x", "f.yaml")
    assert str(e.within("stage")) == "f.yaml: key 'stage.x' must be > 0"
    assert str(e.at("g.yaml")) == "g.yaml: key 'x' must be > 0" and str(e.at(None)) == "key 'x' must be > 0"
    assert type(e.as_(DemoError)) is DemoError and str(e.as_(DemoError)) == str(e)
    assert str(ParamError("plain message")) == "plain message"
    # errors cross process boundaries (sweep workers) unchanged
    again = pickle.loads(pickle.dumps(DemoError("must be > 0", "rotation_hz", "s.yaml")))
    assert type(again) is DemoError and str(again) == "s.yaml: key 'rotation_hz' must be > 0"


# ---------------------------------------------------------------- help and docs
def test_help_text_has_one_aligned_line_per_key_and_sections():
    lines = help_text(schema(Demo), header=True).splitlines()
    assert lines[0].split() == ["key", "type", "default", "unit", "range", "meaning"]
    rows = {line.split()[0]: line for line in lines[1:]}
    assert rows["name"].split()[:3] == ["name", "str", "required"]
    assert rows["frames"].split() == ["frames", "int", "100", "[2,", "1000]", "sweeps", "per", "sequence"]
    assert "null" in rows["speed_m_s"] and "m/s" in rows["speed_m_s"] and "> 0" in rows["speed_m_s"]
    assert "[0]" in rows["seeds"] and "[1.0, 2.0]" in rows["angles_deg"]
    assert rows["stage:"].strip() == "stage: the stage"
    assert "range|isotropic" in rows["stage.model"]
    assert len({line.index(" sweeps") for line in lines if " sweeps" in line}) == 1  # aligned
    assert len({len(line.split("meaning")[0]) for line in lines[:1]} | {rows["frames"].index("sweeps")}) == 1


def test_markdown_table_has_a_row_per_key():
    md = markdown(schema(Demo)).splitlines()
    assert md[0] == "| key | type | default | unit | range | meaning |" and md[1].startswith("|---")
    assert "| `frames` | int | `100` |  | [2, 1000] | sweeps per sequence |" in md
    assert "| `name` | str | required |  |  | a required name |" in md
    assert "| `speed_m_s` | float | `null` | m/s | > 0, or null | cruise speed (null: the scene's own) |" in md
    assert "| **stage** | section | | | | the stage |" in md
    assert "| `stage.model` | str | `range` |  | range, isotropic | noise model |" in md
    assert len(md) == 2 + len(list(schema(Demo).walk()))
