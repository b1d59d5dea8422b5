"""One way to declare parameters: a key's type, unit, default, range and help in one place.

Scene parameters (``scenes``), sensor models (``simlidar.sensor``) and sweep
specs (``tools.sweep.spec``) declare their keys here; the checks and their
one-line errors, the ``--help`` and ``salo scenes NAME`` listings and
``docs/parameters.md`` are made from the declarations. This package imports
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
of its own; in YAML it is a mapping, on the command line a dotted key
(``assignments(["ncf.max_normal_std_deg=3"])``), in errors a dotted name. An
odometry config grouped by stage would read::

    @dataclass(frozen=True)
    class NcfParams(Params):
        section_name = "ncf"
        enabled: bool = param(True, "apply the normal covariance filter")
        max_normal_std_deg: float = param(5.0, "c_tau: largest std of a kept normal", above=0)
        noise_model: str = param("range", "the noise the filter assumes", choices=("range", "isotropic"))

    @dataclass(frozen=True)
    class OdometryConfig(Params):
        name: str = param("salo", "the variant's name")
        voxel_size_m: float = param(0.35, "edge of the voxel grid", above=0)
        ncf: NcfParams = section(NcfParams, "the normal covariance filter")

        def __post_init__(self) -> None:
            super().__post_init__()  # every key; then the rules between keys:
            if self.ncf.enabled and self.voxel_size_m > 2:
                raise ParamError("is too coarse for the NCF", "voxel_size_m")

    OdometryConfig.from_dict({"ncf": {"max_normal_std_deg": 3}}, "my.yaml", base=SALO)
    # my.yaml: key 'ncf.max_normal_std_deg' must be a number > 0 (deg), got -1   (when it is -1)
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
