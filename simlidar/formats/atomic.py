"""Writes that readers never see half done: atomic files, and outputs staged in a hidden folder.

``atomic_write_bytes`` writes a file beside its target and renames it over it.
``StagedFolder`` does the same for a whole output (a sequence folder, a ROS 2
bag, a folder of scans): it is built in the hidden sibling ``.NAME.partial-PID``
holding an ``INCOMPLETE`` marker, and renamed into place only when complete, so
an interrupted write never leaves something that looks finished. A writer
killed outright (SIGKILL, a crash) cannot remove its work folder; the next
writer of the same output removes those of processes that are no longer
running (``remove_stale_partials``).
"""

from __future__ import annotations

import glob
import hashlib
import logging
import os
import shutil
import socket
from pathlib import Path

from ..sequence import DatasetError

log = logging.getLogger(__name__)

INCOMPLETE_MARKER = "INCOMPLETE"


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write a file so that readers see the old content or the new, never a part.

    Written beside the target, synced, then renamed over it; a failed write leaves
    no temporary file behind (the OSError propagates).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        tmp.replace(path)
    except OSError:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write_text(path: str | Path, text: str) -> None:
    """``atomic_write_bytes`` of UTF-8 text."""
    atomic_write_bytes(path, text.encode("utf-8"))


def write_checksummed(path: Path, data) -> str:
    """Write ``data`` (bytes or a byte-format memoryview) to a new file ``path`` in one unbuffered
    write; returns its sha256 (hex), taken from the bytes in memory (no read back).

    Used for the frames of a staged folder (not atomic by itself: the folder is)."""
    with open(path, "wb", buffering=0) as fh:
        fh.write(data)
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


# ---------------------------------------------------------------- staged outputs
def _pid_alive(pid: int) -> bool:
    """Whether process ``pid`` exists on this machine (a process we may not signal counts as alive)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OSError:
        return False
    return True


def remove_stale_partials(out_dir: str | Path) -> list[Path]:
    """Remove the hidden work folders a killed writer of ``out_dir`` left; returns them.

    A writer builds ``.NAME.partial-PID`` beside ``out_dir`` (and, replacing an
    old output, moves that to ``.NAME.old-PID`` for a moment). A process
    killed with SIGKILL cannot clean up, so the next writer of the same
    ``out_dir`` removes those whose process no longer runs, logging a warning
    for each. Left alone: a folder of a live process (another writer at work),
    of this process, with no PID in its name, whose ``INCOMPLETE`` marker names
    another host (a shared file system: its PID means nothing here), or an
    ``old`` one while ``out_dir`` is missing (the swap was cut between its two
    renames: that folder is the only copy of the previous output).
    """
    out_dir = Path(out_dir)
    removed: list[Path] = []
    if not out_dir.parent.is_dir():
        return removed
    host = socket.gethostname()
    for kind in ("partial", "old"):
        for folder in sorted(out_dir.parent.glob(f".{glob.escape(out_dir.name)}.{kind}-*")):
            pid_text = folder.name.rsplit("-", 1)[1]
            if not folder.is_dir() or not pid_text.isdigit():
                continue
            pid = int(pid_text)
            if pid == os.getpid() or _pid_alive(pid) or _marker_host(folder) not in (None, host):
                continue
            if kind == "old" and not out_dir.exists():  # killed mid-swap: the only copy of the old output
                log.warning("%s holds the sequence that process %d was replacing when it stopped; %s is "
                            "missing, so it is left for you to rename back", folder, pid, out_dir)
                continue
            shutil.rmtree(folder, ignore_errors=True)
            if not folder.exists():
                removed.append(folder)
                log.warning("removed %s, left by process %d, which is no longer running (an interrupted "
                            "write of %s)", folder, pid, out_dir.name)
    return removed


def _marker_host(folder: Path) -> str | None:
    """The host named in a work folder's ``INCOMPLETE`` marker, or None (no marker, or none named)."""
    try:
        text = (folder / INCOMPLETE_MARKER).read_text(errors="replace")
    except OSError:
        return None
    for line in text.splitlines():
        key, sep, value = line.partition(":")
        if sep and key.strip() == "host":
            return value.strip()
    return None


def _remove(path: Path) -> None:
    if path.is_dir():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


class StagedFolder:
    """Build an output in ``.NAME.partial-PID`` beside ``out`` and rename it into place when complete.

    Use as a context manager: entering removes stale work folders of dead
    writers (``remove_stale_partials``) and creates the work folder ``path``
    with its ``INCOMPLETE`` marker (host and PID); ``commit()`` moves the
    result to ``out``, replacing an existing ``out`` only then (through
    ``.NAME.old-PID``); leaving the block without a commit (an exception, or a
    writer that gave up) removes the work folder. The result is the work folder
    itself (``commit()``), or an item built inside it under ``out``'s own name
    (``commit(stage.path / out.name)``: for a writer that creates its folder
    itself and names its files after it, as rosbags does).

    An existing ``out`` is refused when the stage is made, unless ``force``;
    ``error`` is the DatasetError subclass raised (refusals, a work folder that
    cannot be created).
    """

    def __init__(self, out: str | Path, force: bool = False, error: type[DatasetError] = DatasetError):
        self.out = Path(out)
        self.error = error
        if self.out.exists() and not force:
            raise error(f"{self.out}: already exists (replace it with --force, or force=True in Python)")
        self.path = self.out.parent / f".{self.out.name}.partial-{os.getpid()}"
        self.removed_stale: list[Path] = []
        self.committed = False

    def __enter__(self) -> StagedFolder:
        try:
            self.out.parent.mkdir(parents=True, exist_ok=True)
            self.removed_stale = remove_stale_partials(self.out)
            if self.path.exists():
                shutil.rmtree(self.path)
            self.path.mkdir()
        except OSError as exc:
            raise self.error(f"{self.out}: cannot create a folder beside it ({exc.strerror})") from None
        (self.path / INCOMPLETE_MARKER).write_text(
            f"a sequence is being written here\nhost: {socket.gethostname()}\npid: {os.getpid()}\n")
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if not self.committed:
            shutil.rmtree(self.path, ignore_errors=True)

    def commit(self, built: Path | None = None) -> Path:
        """Move the finished result (the work folder, or ``built`` inside it) to ``out``; returns ``out``."""
        if built is None:
            (self.path / INCOMPLETE_MARKER).unlink()
            built = self.path
        if self.out.exists():
            trash = self.out.parent / f".{self.out.name}.old-{os.getpid()}"
            self.out.rename(trash)
            built.rename(self.out)
            _remove(trash)
        else:
            built.rename(self.out)
        if built != self.path:
            shutil.rmtree(self.path, ignore_errors=True)
        self.committed = True
        return self.out


__all__ = ["INCOMPLETE_MARKER", "StagedFolder", "atomic_write_bytes", "atomic_write_text", "remove_stale_partials",
           "sha256_file", "write_checksummed"]
