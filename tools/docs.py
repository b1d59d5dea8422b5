"""The parameters page, ``docs/parameters.md``, made from the declarations (``paramspec``).

    python -m tools.docs           # rewrite docs/parameters.md
    python -m tools.docs --check   # exit 1 if the committed page is not what the declarations make

``tests/test_parameters.py`` runs the check, so the page cannot drift from the code.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import scenes
from odometry.config import OdometryConfig, variant_changes
from paramspec import Section, markdown, schema, value_text
from scenes.params import CommonParams
from simlidar.formats.atomic import atomic_write_text
from simlidar.sensor import SENSOR_FILE
from tools.sweep.spec import SweepSpec

PAGE = Path(__file__).resolve().parents[1] / "docs" / "parameters.md"


def parameters_page() -> str:
    """The Markdown page: every scene's parameters, a sensor file's, a sweep spec's and an odometry config's keys."""
    common = {p.name: p for p in schema(CommonParams).members}
    out = [
        "# Parameters",
        "",
        "<!-- Made by `python -m tools.docs` from the declarations (paramspec); do not edit by hand. -->",
        "",
        "Every key below is declared once, in code, with its type, default, unit and range; the checks, their",
        "one-line errors (`FILE: key 'KEY' PROBLEM`), `salo scenes NAME`, `salo sensors --keys`, `salo sweep",
        "--help`, `salo odometry --keys` and this page are made from those declarations. Ranges are inclusive",
        "`[a, b]` or exclusive `(a, b)`; a list key's range holds for each entry. Units: metres, seconds and",
        "degrees as the key's name says (`_m`, `_s`, `_deg`, `_m_s` for m/s, `_pct` for per cent). A dotted key",
        "(`ncf.enabled`) is a key of a section: a mapping in YAML (`ncf: {enabled: false}`).",
        "",
        "## Scenes",
        "",
        "`salo simulate --scene NAME --set KEY=VALUE` or `--scene-params FILE.yaml` (`salo scenes NAME --yaml`",
        "writes one with the defaults), or `scene_params: {NAME: {KEY: VALUE}}` in a sweep spec.",
        "",
        "### Every scene",
        "",
        markdown(Section("scene", tuple(common.values()))),
    ]
    for name, module in scenes.SCENES.items():
        own = [p for p in scenes.scene_parameters(name) if common.get(p.name) != p]
        out += ["", f"### {name}", "", f"{module.DESCRIPTION[:1].upper()}{module.DESCRIPTION[1:]}. Its own "
                "parameters (and the common ones whose default or range it changes):", "",
                markdown(Section(name, tuple(own)))]
    out += [
        "",
        "## Sensor files",
        "",
        "A sensor YAML file (`--sensor FILE.yaml`, a sweep's `sensors`, a scan folder's `sensor.yaml`):",
        f"{SENSOR_FILE.help}. `salo sensors NAME` prints a preset as one. Give `vertical_angles_deg`, or",
        "`ring_pitch_deg` and `lowest_angle_deg`; `azimuth_offsets_deg` has one entry per ring.",
        "",
        markdown(SENSOR_FILE),
        "",
        "## Sweep specs",
        "",
        "`salo sweep SPEC.yaml` (`tools/sweep/README.md`): every key is optional; an axis (`scenes`, `seeds`,",
        "`sensors`, `noise_std_m`, `variants`) is one value or a list.",
        "",
        markdown(schema(SweepSpec)),
        "",
        "## Odometry configs",
        "",
        "`salo odometry --config FILE.yaml` (any subset of the keys: a mapping per stage, `ncf:",
        "{max_normal_std_deg: 3}`), `--set STAGE.KEY=VALUE` (`salo odometry`, `salo experiment ...`), a sweep",
        "spec's `odometry` and `configs`. `salo odometry --keys` lists them too. Between keys:",
        "`clean.min_range_m` < `clean.max_range_m`; `ncf.applies_to` other than `scan` needs `match.target: map`.",
        "The defaults are the `salo` variant's.",
        "",
        markdown(schema(OdometryConfig)),
        "",
        "The variants (`--variant`, a sweep's `variants`) change:",
        "",
        "| variant | changes to the defaults |",
        "|---|---|",
        *[f"| `{name}` | {', '.join(f'`{k}: {value_text(v)}`' for k, v in changes.items()) or 'nothing'} |"
          for name, changes in variant_changes().items()],
        "",
    ]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tools.docs", description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if the page differs from the declarations")
    args = parser.parse_args(argv)
    page = parameters_page()
    if args.check:
        current = PAGE.read_text() if PAGE.exists() else ""
        if current != page:
            sys.stderr.write(f"{PAGE} is out of date: run python -m tools.docs\n")
            return 1
        return 0
    PAGE.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(PAGE, page)
    sys.stdout.write(f"wrote {PAGE}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
