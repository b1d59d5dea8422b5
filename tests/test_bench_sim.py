"""The simulation benchmark's floor: the frame files it writes go through the writer's own function.

The benchmark prints figures and asserts nothing; these tests check that what it
measures is the real work (files of the sequence's sizes, written and checksummed
the way ``SequenceWriter`` writes them), not its speed.
"""

from __future__ import annotations

import hashlib

import numpy as np

from simlidar.formats.atomic import write_checksummed
from tools.bench_sim import floor_write_cpu_s


def test_write_checksummed_writes_the_bytes_and_returns_their_sha256(tmp_path):
    points = np.arange(40, dtype="<f4").reshape(10, 4)
    path = tmp_path / "000000.bin"
    digest = write_checksummed(path, memoryview(points).cast("B"))
    on_disk = path.read_bytes()
    assert on_disk == points.tobytes()
    assert digest == hashlib.sha256(on_disk).hexdigest()


def test_the_floor_writes_each_frame_the_sequences_bytes(tmp_path):
    frames, sizes = 3, {"velodyne": 3 * 1600, "sidecar": 3 * 1400 + 2}  # the remainder is dropped
    floor_write_cpu_s(tmp_path / "floor", frames, sizes)
    files = sorted((tmp_path / "floor").iterdir())
    assert len(files) == frames * len(sizes)
    assert sorted({f.stat().st_size for f in files}) == [1400, 1600]
