"""How big and how quick the HTML view is: a sequence's page, its size, and its load in headless Chromium.

    python -m tools.bench_view [--sequence SEQ] [--frames 200] [--sensor hdl64e] [--out DIR] [--rounds 3]

Without --sequence it simulates ``--frames`` sweeps of ``--sensor`` through the
city (once; kept in ``DIR/sequence``). It writes the page (``tools.view_html``),
then opens it in headless Chromium (Debian's ``chromium``): a blank page (the
browser's own start, the reference), the page until its first frame is drawn,
and the page drawing every frame once in order (``#walk``). Each is the
browser's wall time, the median of ``--rounds``: it includes the drawing, which
WebGL hands to the browser's GPU process (without a GPU, SwiftShader draws on the
CPU); the page's own clock (``performance.now()``, the script's side only) is
printed beside it.
"""

from __future__ import annotations

import argparse
import re
import shutil
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--use-angle=swiftshader", "--enable-unsafe-swiftshader")


def load(url: str, budget_ms: int = 600000) -> tuple[float, dict]:
    """Wall time, s, of headless Chromium loading ``url`` until it is idle, and the page's body attributes."""
    binary = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if binary is None:
        raise SystemExit("no chromium on PATH: apt-get install -y chromium")
    with tempfile.TemporaryDirectory(prefix="salo-chromium-") as profile:
        t0 = time.perf_counter()
        out = subprocess.run([binary, *FLAGS, f"--user-data-dir={profile}", "--window-size=1400,950",
                              f"--virtual-time-budget={budget_ms}", "--dump-dom", url], capture_output=True,
                             text=True, timeout=budget_ms / 1000 + 120).stdout
        seconds = time.perf_counter() - t0
    body = re.search(r"<body([^>]*)>", out)
    return seconds, dict(re.findall(r'data-([\w-]+)="([^"]*)"', body.group(1) if body else ""))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sequence", type=Path, help="a sequence folder (default: simulate one)")
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--sensor", default="hdl64e")
    parser.add_argument("--max-points", type=int, help="at most this many points a frame on the page")
    parser.add_argument("--out", type=Path, default=Path("out/bench_view"))
    parser.add_argument("--rounds", type=int, default=3, help="loads timed per case (the median is printed)")
    parser.add_argument("--walk-rounds", type=int, default=1, help="timed walks through every frame")
    args = parser.parse_args(argv)

    from simlidar.dataset import open_sequence
    from tools import view_html

    sequence = args.sequence
    if sequence is None:
        sequence = args.out / "sequence"
        if not (sequence / "manifest.json").is_file():
            from simlidar.sensor import load_sensor
            from tools.runners import simulate_scene
            from tools.worlds import build_scene_world

            print(f"simulating {args.frames} sweeps of {args.sensor} through the city into {sequence}")
            simulate_scene(build_scene_world("city", 0, {"speed_m_s": 8.0}), load_sensor(args.sensor), sequence,
                           args.frames, seed=0, start_s=4.0, force=True)
    seq = open_sequence(sequence)
    frames = min(args.frames, len(seq))
    t0 = time.perf_counter()
    data = view_html.sequence_page(sequence, frames=slice(0, frames), max_points=args.max_points)
    page = view_html.write_page(data, args.out / "page.html")
    write_s = time.perf_counter() - t0
    points = sum(len(p) for p in data.points)
    size = page.stat().st_size
    print(f"page: {page}: {frames} frames of {seq.sensor.name} ({seq.sensor.rings} rings), {points} points "
          f"({points / frames:.0f} a frame), {size / 1e6:.1f} MB ({size / points:.2f} bytes a point, "
          f"{size / frames / 1e3:.0f} kB a frame); written in {write_s:.1f} s", flush=True)
    blank = args.out / "blank.html"
    blank.write_text("<!DOCTYPE html><html><body data-status=\"drawn\">blank</body></html>")
    results = {}
    for name, url, rounds in (("blank page (reference)", blank.resolve().as_uri(), args.rounds),
                              ("page, first frame drawn", page.resolve().as_uri() + "#frame=0", args.rounds),
                              ("page, every frame drawn once, one scan a frame",
                               page.resolve().as_uri() + "#walk=1&trail=0", args.walk_rounds),
                              ("page, every frame drawn once, with the default trail (3 scans a frame)",
                               page.resolve().as_uri() + "#walk=1", args.walk_rounds)):
        runs = [load(url) for _ in range(rounds)]
        wall = statistics.median(s for s, _ in runs)
        results[name] = wall
        attrs = runs[-1][1]
        inside = ""
        if "first-draw-ms" in attrs and "walk" not in url:  # the script's side; a walk's drawing is the GPU's
            inside += f"; the page's clock: first frame at {int(attrs['first-draw-ms']) / 1000:.2f} s"
        status = attrs.get("status", "?")
        print(f"{name}: {wall:.2f} s wall (median of {rounds}; status {status}){inside}", flush=True)
    ref = results["blank page (reference)"]
    first = results["page, first frame drawn"] - ref
    print(f"beyond the browser's own start: first frame {first:.2f} s", flush=True)
    for name, wall in results.items():
        if "every frame" in name:
            print(f"  {name}: {wall - ref:.1f} s, {(wall - ref - first) / (frames - 1) * 1000:.0f} ms a frame "
                  "after the first", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
