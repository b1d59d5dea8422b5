"""One way to declare parameters: a key's type, unit, default, range and help in one place.

Scene parameters (``scenes``), sensor models (``simlidar.sensor``), sweep
specs (``tools.sweep.spec``) and odometry configs (``odometry.config``) declare
their keys here; the checks and their one-line errors, the ``--help``, ``--keys``
and ``salo scenes NAME`` listings and ``docs/parameters.md`` are made from the
declarations. This package imports
nothing of the project (and only the standard library), so every package may
import it.

Declaring: a frozen dataclass deriving from ``Params``, each field a ``param``
(the type from the annotation, the unit from the name's suffix)::

    @dataclass(frozen=True)
    class Budget(Params):
        frames: int = param(100, "sweeps per sequence", min=2)
        speed_m_s: float | None = param(None, "cruise speed (null: the scene's own)", above=0)
        shape: str = param("arch", "shape of the bore", choices=("arch", "box"))

    Budget(frames=1)                                  # ParamError: key 'frames' must be an integer >= 2, got 1
    Budget.from_dict({"frame": 3}, "b.yaml")          # b.yaml: key 'frame' is unknown; did you mean 'frames'? ...
    Budget.from_dict({"frames": "30"}, coerce=True)   # command-line text: frames=30
    help_text(schema(Budget)), markdown(schema(Budget))

Nested sections: a field declared with ``section(cls, help)`` holds a ``Params``
of its own (its switch, by convention, the bool key ``enabled``); in YAML it is a
mapping, on the command line a dotted key (``assignments(["ncf.max_normal_std_deg=3"])``),
in errors a dotted name. The odometry config is grouped by stage so
(``odometry/config.py``, abridged)::

    @dataclass(frozen=True)
    class NcfParams(Params):
        section_name = "ncf"
        enabled: bool = param(True, "apply the normal covariance filter")
        noise_model: str = param("range", "the noise the filter assumes", choices=("range", "isotropic"))
        max_normal_std_deg: float = param(5.0, "c_tau: largest std of a kept normal", above=0)
        applies_to: str = param("scan", "whose normals it judges", choices=("scan", "map", "both"))

    @dataclass(frozen=True)
    class OdometryConfig(Params):
        error = ConfigError
        name: str = param("salo", "the variant's name")
        ncf: NcfParams = section(NcfParams)     # help: the class docstring's first line
        match: MatchParams = section(MatchParams)

        def __post_init__(self) -> None:
            super().__post_init__()  # every key; then the rules between keys:
            if self.ncf.applies_to != "scan" and self.match.target != "map":
                raise ConfigError("needs match.target: map", "ncf.applies_to")

    OdometryConfig.from_dict({"ncf": {"max_normal_std_deg": 3}}, "my.yaml", base=SALO)
    # my.yaml: key 'ncf.max_normal_std_deg' must be a number > 0 (deg), got -1   (when it is -1)
    OdometryConfig.from_dict(assignments(["ncf_max_normal_std_deg=3"]), "--set", coerce=True, base=SALO)
    # --set: key 'ncf_max_normal_std_deg' is unknown; did you mean 'ncf.max_normal_std_deg'?
    differences(SALO_MAP, SALO)   # {'name': 'salo-map', 'ncf.applies_to': 'map', 'match.target': 'map'}
"""

from .declare import (
    REQUIRED,
    Param,
    ParamError,
    Params,
    Section,
    assignments,
    build,
    check,
    differences,
    param,
    schema,
    section,
    show,
    unit_of,
    unknown,
)
from .render import default_text, help_text, markdown, range_text, value_text

__all__ = [
    "REQUIRED",
    "Param",
    "ParamError",
    "Params",
    "Section",
    "assignments",
    "build",
    "check",
    "default_text",
    "differences",
    "help_text",
    "markdown",
    "param",
    "range_text",
    "schema",
    "section",
    "show",
    "unit_of",
    "unknown",
    "value_text",
]
