"""``salo sensors``: the sensor presets, or one of them as YAML."""

from __future__ import annotations

from simlidar.sensor import load_sensor, preset_names


def add_commands(sub) -> None:
    p = sub.add_parser("sensors", help="list sensor presets, or print one as YAML")
    p.add_argument("name", nargs="?", help="preset to print")
    p.set_defaults(func=cmd_sensors)


def cmd_sensors(args) -> int:
    if args.name:
        print(load_sensor(args.name).to_yaml(), end="")
        return 0
    for name in preset_names():
        m = load_sensor(name)
        print(
            f"{name:8s} {m.rings:3d} rings  phi {m.azimuth_step_deg:.4f} deg  "
            f"{m.rotation_hz:g} Hz  {m.rays_per_sweep:6d} rays/sweep  {m.description}"
        )
    return 0
