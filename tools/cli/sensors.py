"""``salo sensors``: the sensor presets, one of them as YAML, or the keys of a sensor file."""

from __future__ import annotations

from paramspec import help_text
from simlidar.sensor import SENSOR_FILE, load_sensor, preset_names


def add_commands(sub) -> None:
    p = sub.add_parser("sensors", help="list sensor presets, print one as YAML, or list a sensor file's keys",
                       description="List the sensor presets; with NAME, print that preset as a sensor YAML "
                       "file; with --keys, list the keys of a sensor file (type, default, unit, range, meaning).")
    p.add_argument("name", nargs="?", help="preset to print")
    p.add_argument("--keys", action="store_true", help="list the keys of a sensor YAML file")
    p.set_defaults(func=cmd_sensors)


def cmd_sensors(args) -> int:
    if args.keys:
        print(f"The keys of a sensor YAML file: {SENSOR_FILE.help} (`salo sensors NAME` prints a preset as one).")
        print(help_text(SENSOR_FILE, header=True))
        return 0
    if args.name:
        print(load_sensor(args.name).to_yaml(), end="")
        return 0
    for name in preset_names():
        m = load_sensor(name)
        print(
            f"{name:8s} {m.rings:3d} rings  phi {m.azimuth_step_deg:.4f} deg  "
            f"{m.rotation_hz:g} Hz  {m.rays_per_sweep:6d} rays/sweep  {m.description}"
        )
    print("\n`salo sensors NAME` prints a preset as YAML; `salo sensors --keys` lists a sensor file's keys")
    return 0
