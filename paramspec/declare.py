"""Declaring parameters, and reading dicts and ``KEY=VALUE`` text against the declarations.

A ``Param`` is one key: name, type, unit, default, bounds or choices, nullable, help.
A ``Section`` is a named group of keys and of nested sections. ``Params`` is the
base of frozen dataclasses whose fields are declared with ``param`` (a key) and
``section`` (a nested group); ``schema(cls)`` reads the declarations into a
``Section``. Every error is a ``ParamError``: one line, ``"{origin}: key '{key}'
{problem}"``, the problem a predicate ("must be an integer in [2, 12], got 1").
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import math
import numbers
import types
import typing
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

MISSING = dataclasses.MISSING


class _Required:
    """The default of a required key (there is none)."""

    def __repr__(self) -> str:
        return "REQUIRED"


REQUIRED = _Required()
SCALARS = ("bool", "int", "float", "str")
# The project names its quantities with their units (speed_m_s, azimuth_step_deg): a key's unit
# is read from its name unless declared. Longer suffixes first.
UNIT_SUFFIXES = (
    ("_m_s2", "m/s^2"), ("_m_s", "m/s"), ("_per_100m", "1/100 m"), ("_per_ha", "1/ha"), ("_deg", "deg"),
    ("_pct", "%"), ("_hz", "Hz"), ("_m", "m"), ("_s", "s"),
)
_KINDS = {"bool": "true or false", "int": "an integer", "float": "a number", "str": "a string"}
_PLURALS = {"bool": "true/false values", "int": "integers", "float": "numbers", "str": "strings"}
_TRUE = ("1", "true", "yes", "on")
_FALSE = ("0", "false", "no", "off")


def unit_of(name: str) -> str:
    """The unit a key's name carries by the project's convention ('' when it carries none)."""
    for suffix, unit in UNIT_SUFFIXES:
        if name.endswith(suffix):
            return unit
    return ""


def show(value: Any) -> str:
    """A value as an error message quotes it: YAML's null / true / false, else ``repr``."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value)


def number_text(x: float) -> str:
    """A bound as text: 360.0 -> '360', 1e6 -> '1000000', 0.25 -> '0.25'."""
    if isinstance(x, float) and x.is_integer() and abs(x) < 1e15:
        return str(int(x))
    return repr(x) if isinstance(x, float) else str(x)


class ParamError(ValueError):
    """An invalid parameter: ``"{origin}: key '{key}' {problem}"`` in one line.

    ``problem`` is a predicate ("must be a number > 0 (Hz), got 'fast'", "is
    missing", "is unknown; did you mean 'scenes'? (known: ...)"). Without a key
    the text is ``"{origin}: {problem}"``; without an origin it starts at the key.
    Subclasses (``SensorError``, ``SpecError``) keep the same shape.
    """

    def __init__(self, problem: str, key: str | None = None, origin: str | None = None,
                 suggestion: str | None = None):
        self.problem, self.key, self.origin, self.suggestion = problem, key, origin, suggestion
        text = problem if key is None else f"key '{key}' {problem}"
        super().__init__(text if origin is None else f"{origin}: {text}")

    def at(self, origin: str | None) -> ParamError:
        """The same error, said of ``origin`` (a file, a scene, a sensor: it replaces the one it had)."""
        return type(self)(self.problem, self.key, origin, self.suggestion)

    def within(self, key: str) -> ParamError:
        """The same error one section down: its key becomes ``key.<its key>``, and so does the name it
        suggests (``did you mean 'filter.voxel_size_m'?``: the whole key, to be given as it is)."""
        problem, suggestion = self.problem, self.suggestion
        if suggestion is not None:
            problem = problem.replace(f"did you mean '{suggestion}'", f"did you mean '{key}.{suggestion}'", 1)
            suggestion = f"{key}.{suggestion}"
        return type(self)(problem, key if self.key is None else f"{key}.{self.key}", self.origin, suggestion)

    def as_(self, error: type[ParamError]) -> ParamError:
        """The same error as another class of ``ParamError`` (a section's own)."""
        return self if type(self) is error else error(self.problem, self.key, self.origin, self.suggestion)


# ---------------------------------------------------------------- one key
@dataclass(frozen=True)
class Param:
    """One key.

    type: ``bool``, ``int``, ``float``, ``str``, ``list[<one of those>]`` or
    ``mapping`` (names to values, checked by the owner). default: ``REQUIRED``
    for a required key. min / max bound a number inclusively, above / below
    exclusively (a list's every entry). nullable: null is a value. one_or_more:
    a single value is a one-element list (a sweep's axis). unique: a list may not
    hold a value twice. check: an extra rule, value -> the problem or None.
    """

    name: str
    type: str
    default: Any = REQUIRED
    help: str = ""
    unit: str = ""
    min: float | None = None
    max: float | None = None
    above: float | None = None
    below: float | None = None
    choices: tuple | None = None
    nullable: bool = False
    one_or_more: bool = False
    unique: bool = False
    check: Callable[[Any], str | None] | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.item not in SCALARS and self.type != "mapping":
            raise TypeError(f"parameter {self.name}: unknown type {self.type!r}")

    @property
    def required(self) -> bool:
        return self.default is REQUIRED

    @property
    def is_list(self) -> bool:
        return self.type.startswith("list[")

    @property
    def item(self) -> str:
        """The type of one value: a list's entries', else the key's own."""
        return self.type[5:-1] if self.is_list else self.type

    def bounds(self) -> str:
        """The range as text: '[2, 12]', '(0, 360]', '>= 0', '< 1', or ''."""
        lo, lo_open = (self.above, True) if self.above is not None else (self.min, False)
        hi, hi_open = (self.below, True) if self.below is not None else (self.max, False)
        if lo is not None and hi is not None:
            return f"{'(' if lo_open else '['}{number_text(lo)}, {number_text(hi)}{')' if hi_open else ']'}"
        if lo is not None:
            return f"{'>' if lo_open else '>='} {number_text(lo)}"
        if hi is not None:
            return f"{'<' if hi_open else '<='} {number_text(hi)}"
        return ""

    def expects(self, entry: bool = False) -> str:
        """What a value must be, as the errors say it: 'an integer in [2, 12]', 'a number >= 0 (m) or null'.

        ``entry``: one entry of a list key.
        """
        if self.type == "mapping":
            text = "a mapping of names to values"
        elif self.is_list and not entry:
            text = f"a list of {_PLURALS[self.item]}"
        elif self.choices is not None:
            text = f"one of {', '.join(str(c) for c in self.choices)}"
        else:
            text = _KINDS[self.item]
        if self.item in ("int", "float") and self.choices is None:
            bounds = self.bounds()
            if bounds:
                text += f" {bounds}" if bounds[0] in "<>" else f" in {bounds}"
            if self.unit:
                text += f" ({self.unit})"
        if self.is_list and not entry and self.one_or_more:
            text = f"{_KINDS[self.item]} or {text}"
        if self.nullable and not entry:
            text += " or null"
        return text

    # ---- reading a value
    def convert(self, value: Any, coerce: bool = False) -> Any:
        """``value`` checked against the declaration (a list becomes a tuple).

        ``coerce``: ``value`` may be command-line text or loosely typed ('250'
        and 250.0 for an int, 'yes' and 1 for a bool, 250 -> 250.0 for a float,
        'null' for null where null is a value);
        otherwise it must have the key's type (an int is a number; a number is
        kept as given). Raises ``ParamError`` naming this key.
        """
        if coerce and self.nullable and isinstance(value, str) and value.strip() == "null":
            value = None  # command-line text: YAML's null
        if value is None:
            if self.nullable:
                return None
            if self.type == "mapping":
                return {}  # an empty YAML section reads as null
            raise self.fail(f"must be {self.expects()}, got null")
        if self.type == "mapping":
            if not isinstance(value, Mapping) or not all(isinstance(k, str) for k in value):
                raise self.fail(f"must be {self.expects()}, got {type(value).__name__}")
            value = dict(value)
        elif self.is_list:
            value = self._convert_list(value, coerce)
        else:
            value = self._convert_one(value, coerce, entry=False)
        if self.check is not None:
            problem = self.check(value)
            if problem:
                raise self.fail(problem)
        return value

    def fail(self, problem: str) -> ParamError:
        return ParamError(problem, self.name)

    def _convert_list(self, value: Any, coerce: bool) -> tuple:
        if isinstance(value, list | tuple):
            items = list(value)
        elif coerce and isinstance(value, str):  # command-line text: a,b,c
            items = [v.strip() for v in value.split(",")] if value.strip() else []
        elif self.one_or_more:
            items = [value]
        else:
            raise self.fail(f"must be {self.expects()}, got {show(value)}")
        if not items:
            hint = "" if self.required else " (leave the key out for its default)"
            raise self.fail(f"is empty{hint}")
        out = tuple(self._convert_one(v, coerce, entry=True) for v in items)
        if self.unique:
            seen = []
            for v in out:
                if v in seen:
                    raise self.fail(f"lists {show(v)} twice")
                seen.append(v)
        return out

    def _convert_one(self, value: Any, coerce: bool, entry: bool) -> Any:
        def bad(got: Any) -> ParamError:  # the value as read: '-2' given as text is -2 out of range
            if entry:
                return self.fail(f"has {show(got)}, which is not {self.expects(entry=True)}")
            return self.fail(f"must be {self.expects()}, got {show(got)}")

        try:
            v = _cast(self.item, value, coerce)
        except (TypeError, ValueError):
            raise bad(value) from None
        if self.choices is not None and v not in self.choices:
            raise bad(value)
        if self.item == "float" and not math.isfinite(v):
            raise bad(v)
        if self.item in ("int", "float") and not _in_bounds(self, v):
            raise bad(v)
        return v


def _cast(kind: str, value: Any, coerce: bool) -> Any:
    """``value`` as ``kind``; TypeError / ValueError when it is not one (see ``Param.convert``)."""
    if kind == "bool":
        if isinstance(value, bool):
            return value
        if coerce and isinstance(value, str) and value.strip().lower() in _TRUE + _FALSE:
            return value.strip().lower() in _TRUE
        if coerce and isinstance(value, numbers.Integral) and value in (0, 1):
            return bool(value)
        raise TypeError
    if isinstance(value, bool):  # True is an int to Python, never a number here
        raise TypeError
    if kind == "int":
        if isinstance(value, numbers.Integral):
            return int(value)
        if coerce and isinstance(value, numbers.Real) and float(value).is_integer():
            return int(value)
        if coerce and isinstance(value, str):
            return int(value.strip().replace("_", ""))
        raise TypeError
    if kind == "float":
        if isinstance(value, numbers.Real):
            return float(value) if coerce else value
        if coerce and isinstance(value, str):
            return float(value)
        raise TypeError
    if isinstance(value, str):
        return value
    if coerce and isinstance(value, numbers.Real):
        return str(value)
    raise TypeError


def _in_bounds(p: Param, v: float) -> bool:
    return ((p.min is None or v >= p.min) and (p.max is None or v <= p.max)
            and (p.above is None or v > p.above) and (p.below is None or v < p.below))


# ---------------------------------------------------------------- a group of keys
@dataclass(frozen=True)
class Section:
    """A named group of keys and nested sections; ``cls``: the ``Params`` class it builds, if any.

    A section's on/off switch is, by convention, its bool key ``enabled``.
    """

    name: str
    members: tuple[Param | Section, ...]
    help: str = ""
    cls: type | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        names = [m.name for m in self.members]
        if len(set(names)) != len(names):
            raise TypeError(f"section {self.name}: a key declared twice")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(m.name for m in self.members)

    def __getitem__(self, name: str) -> Param | Section:
        for m in self.members:
            if m.name == name:
                return m
        raise KeyError(name)

    def walk(self, prefix: str = "") -> Iterator[tuple[str, Param | Section]]:
        """(dotted name, member) of every key and section, depth first, in declaration order."""
        for m in self.members:
            yield prefix + m.name, m
            if isinstance(m, Section):
                yield from m.walk(f"{prefix}{m.name}.")

    def read(self, data: Any, origin: str | None = None, *, coerce: bool = False, partial: bool = False,
             error: type[ParamError] = ParamError) -> dict:
        """The keys given in ``data``, checked and converted (nested sections as dicts).

        Unknown keys (with the closest known name), missing required keys (unless
        ``partial``: an overlay on values that have them), wrong types, values out
        of range: ``error`` naming ``origin`` and the dotted key. Keys left out
        are left out (defaults are the builder's business).
        """
        try:
            return self._read(data, coerce, partial)
        except ParamError as exc:
            raise exc.as_(error).at(origin) from None

    def _read(self, data: Any, coerce: bool, partial: bool = False) -> dict:
        if not isinstance(data, Mapping):
            raise ParamError(f"expected a mapping of {self.name} keys, got {type(data).__name__}")
        for key in data:
            if key not in self.names:
                moved = self.moved(str(key))
                raise ParamError(f"is unknown; did you mean '{moved}'?" if moved else unknown(str(key), self.names),
                                 str(key), suggestion=moved or closest(str(key), self.names))
        for m in self.members:
            if isinstance(m, Param) and m.required and m.name not in data and not partial:
                raise ParamError(f"is missing ({m.help})" if m.help else "is missing", m.name)
        out = {}
        for key, value in data.items():
            m = self[key]
            if isinstance(m, Section):
                if value is not None and not isinstance(value, Mapping):
                    raise ParamError(m.not_a_mapping(value), key)
                try:
                    out[key] = m._read(value or {}, coerce, partial)
                except ParamError as exc:
                    raise exc.within(key) from None
            else:
                out[key] = m.convert(value, coerce)
        return out


    def moved(self, key: str) -> str | None:
        """The dotted name of the nested key that ``key``, unknown here, most likely means, or None.

        A key that moved into a section: one whose own name is ``key``
        (``voxel_size_m`` -> ``filter.voxel_size_m``), or whose section's name,
        '_' and own name make ``key`` (``match_target`` -> ``match.target``); the
        first in declaration order. (A single value given for a section with an
        ``enabled`` switch, ``ncf: false``, is pointed at it: ``not_a_mapping``.)
        """
        for name, m in self.walk():
            section, _, leaf = name.rpartition(".")
            if section and isinstance(m, Param) and key in (leaf, f"{section.rpartition('.')[2]}_{leaf}"):
                return name
        return None

    def not_a_mapping(self, value: Any) -> str:
        """The problem of a single value given for this section (pointing at its switch, if it has one)."""
        hint = f"; did you mean '{self.name}.enabled'?" if _switch(self) else ""
        return f"must be a mapping of {self.name} keys, got {type(value).__name__}{hint}"


def _switch(sec: Section) -> bool:
    return "enabled" in sec.names and getattr(sec["enabled"], "type", None) == "bool"


def closest(key: str, names: Iterable[str]) -> str | None:
    """The known name an unknown ``key`` most likely means, or None when none is close."""
    names = list(names)
    # A unit suffix left out ('speed' for speed_m_s) is the commonest slip; then the closest spelling.
    close = [key + suffix for suffix, _ in UNIT_SUFFIXES if key + suffix in names][:1] or difflib.get_close_matches(
        key, names, n=1, cutoff=0.6)
    return close[0] if close else None


def unknown(key: str, names: Iterable[str]) -> str:
    """The problem of an unknown key: the closest known name, if one is close, and the known ones."""
    names = list(names)
    close = closest(key, names)
    hint = f"; did you mean '{close}'?" if close else ""
    return f"is unknown{hint} (known: {', '.join(names)})"


# ---------------------------------------------------------------- declaring dataclass fields
def param(default: Any = MISSING, help: str = "", *, unit: str | None = None, min: float | None = None,
          max: float | None = None, above: float | None = None, below: float | None = None,
          choices: tuple | None = None, nullable: bool = False, one_or_more: bool = False, unique: bool = False,
          check: Callable[[Any], str | None] | None = None) -> Any:
    """A dataclass field declaring one key (see ``Param``); no ``default``: a required key.

    The type comes from the field's annotation (``X | None`` makes it nullable;
    ``tuple[float, ...]`` is ``list[float]``; ``dict`` is ``mapping``); the unit
    from the name's suffix unless ``unit`` is given ('' for none).
    """
    meta = {"param": dict(help=help, unit=unit, min=min, max=max, above=above, below=below, choices=choices,
                          nullable=nullable, one_or_more=one_or_more, unique=unique, check=check)}
    if isinstance(default, dict | list):  # a mutable default: each instance its own copy
        return field(default_factory=lambda: type(default)(default), metadata=meta)
    return field(default=default, metadata=meta)


def section(cls: type, help: str = "") -> Any:
    """A dataclass field holding a nested section: an instance of the ``Params`` class ``cls``."""
    return field(default_factory=cls, metadata={"section": help})


def _type_of(hint: Any, where: str) -> tuple[str, bool]:
    """(Param type, nullable) of an annotation."""
    nullable = False
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        if len(args) != 1 or len(args) == len(typing.get_args(hint)):
            raise TypeError(f"{where}: only 'X | None' unions are parameters, got {hint}")
        hint, nullable = args[0], True
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint in (bool, int, float, str):
        return hint.__name__, nullable
    if origin in (tuple, list) and args and args[0] in (bool, int, float, str) and args[1:] in ((), (Ellipsis,)):
        return f"list[{args[0].__name__}]", nullable
    if hint is dict or origin is dict:
        return "mapping", nullable
    raise TypeError(f"{where}: {hint} is not a parameter type (bool, int, float, str, tuple[X, ...], dict)")


@functools.cache
def schema(cls: type) -> Section:
    """The declarations of a ``Params`` dataclass as a ``Section`` (named ``section_name``; help: its docstring)."""
    hints = typing.get_type_hints(cls)
    members: list[Param | Section] = []
    for f in dataclasses.fields(cls):
        where = f"{cls.__name__}.{f.name}"
        if "section" in f.metadata:
            sub = schema(hints[f.name])
            members.append(dataclasses.replace(sub, name=f.name, help=f.metadata["section"] or sub.help))
            continue
        if "param" not in f.metadata:
            raise TypeError(f"{where}: declare it with param() or section()")
        meta = dict(f.metadata["param"])
        type_name, nullable = _type_of(hints[f.name], where)
        default = f.default_factory() if f.default_factory is not MISSING else (
            REQUIRED if f.default is MISSING else f.default)
        declared_unit = meta.pop("unit")
        unit = unit_of(f.name) if declared_unit is None else declared_unit
        meta["nullable"] = meta["nullable"] or nullable
        members.append(Param(f.name, type_name, default, unit=unit, **meta))
    doc = (cls.__doc__ or "").strip().splitlines()
    help = doc[0] if doc and not doc[0].startswith(cls.__name__ + "(") else ""
    return Section(getattr(cls, "section_name", None) or cls.__name__, tuple(members), help, cls)


class Params:
    """Base of a frozen dataclass of declared parameters, validated whenever one is built.

    Class attributes (not fields): ``error``, the ``ParamError`` subclass its
    errors are; ``section_name``, its name in messages and documents.
    """

    error: typing.ClassVar[type[ParamError]] = ParamError
    section_name: typing.ClassVar[str | None] = None

    def __post_init__(self) -> None:
        check(self)

    @classmethod
    def schema(cls) -> Section:
        return schema(cls)

    @classmethod
    def from_dict(cls, data: Any, origin: str | None = None, *, coerce: bool = False, base: Any = None):
        """An instance from a YAML-style dict (``coerce``: values may be command-line text).

        Keys left out keep ``base``'s values (default: the declared defaults);
        a nested section's keys overlay the base's section. Errors are
        ``cls.error`` naming ``origin`` and the dotted key.
        """
        values = schema(cls).read(data, origin, coerce=coerce, partial=base is not None, error=cls.error)
        return build(cls, values, base, origin)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def build(cls: type, values: dict, base: Any = None, origin: str | None = None):
    """An instance of ``cls`` from ``Section.read`` output overlaid on ``base`` (or the defaults)."""
    try:
        return _build(cls, values, base)
    except ParamError as exc:
        raise exc.as_(getattr(cls, "error", ParamError)).at(origin if origin is not None else exc.origin) from None


def _build(cls: type, values: dict, base: Any):
    kwargs = {}
    for m in schema(cls).members:
        if m.name not in values:
            continue
        if isinstance(m, Section):
            try:
                kwargs[m.name] = _build(m.cls, values[m.name], None if base is None else getattr(base, m.name))
            except ParamError as exc:
                raise exc.within(m.name) from None
        else:
            kwargs[m.name] = values[m.name]
    return dataclasses.replace(base, **kwargs) if base is not None else cls(**kwargs)


def check(obj: Any) -> None:
    """Validate every declared field of ``obj`` in place (strict types; lists become tuples).

    A nested section may be given as a dict: it is read into its class.
    Raises ``type(obj).error``.
    """
    cls = type(obj)
    error = getattr(cls, "error", ParamError)
    for m in schema(cls).members:
        value = getattr(obj, m.name)
        try:
            if not isinstance(m, Section):
                new = m.convert(value)
            elif isinstance(value, m.cls):
                new = value
            elif isinstance(value, Mapping):
                try:
                    new = m.cls.from_dict(value)
                except ParamError as exc:
                    raise exc.within(m.name) from None
            else:
                raise ParamError(m.not_a_mapping(value), m.name)
        except ParamError as exc:
            raise exc.as_(error) from None
        if new is not value:
            object.__setattr__(obj, m.name, new)


def differences(obj: Any, base: Any) -> dict:
    """``{dotted key: obj's value}`` for every key where ``obj`` differs from ``base`` (of the same class)."""
    out = {}
    for name, m in schema(type(obj)).walk():
        if isinstance(m, Param):
            value = functools.reduce(getattr, name.split("."), obj)
            if value != functools.reduce(getattr, name.split("."), base):
                out[name] = value
    return out


def assignments(pairs: Iterable[str], what: str = "--set") -> dict:
    """``KEY=VALUE`` strings as a dict of text; ``section.key=VALUE`` goes into the nested dict.

    Read the result with ``coerce=True``. A pair without '=' or key is a
    ``ParamError`` naming it (``"{what} 'x': expected KEY=VALUE"``).
    """
    out: dict = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        key = key.strip()
        path = key.split(".")
        if not sep or not all(path):
            raise ParamError("expected KEY=VALUE", origin=f"{what} {pair!r}")
        node = out
        for part in path[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):
                raise ParamError(f"{part} is a key, not a section", origin=f"{what} {pair!r}")
        node[path[-1]] = value.strip()
    return out
