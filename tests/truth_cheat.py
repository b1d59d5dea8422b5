"""A method that tries to read the ground truth instead of estimating: the cheat of tests/test_truth_out_of_reach.py.

Copied next to a plug-in package and a command script by the test. ``search`` looks
everywhere a method could be led by what it is handed:

- by link target: every given path, and every entry below a given folder, that is a
  symbolic link is followed, and the folder it leads to searched;
- by inode: a file with more than one name (a hard link) is another name of a file
  somewhere; the trees above it are searched for a file of the same inode, and the truth
  beside each other name is taken (a git clone's hard-linked objects set this off too:
  it then finds their other names and nothing else);
- walking up: from every given path (arguments, the working folder, every path in an
  environment variable), each folder above it and its sub-folders two levels down are
  searched, as ``{scans}/../poses.txt`` or ``$(dirname $PWD)/*/poses.txt`` would;
- and every given folder is searched to the bottom.

It reports every file named like the truth (``TRUTH_NAMES``) that it reached; the test
decides which of them hold this sequence's truth. Only the standard library, so it
runs as a command too (``python truth_cheat.py ARGS... {scans} {out}``: a report line appended to
``$SALO_CHEAT_REPORT``, the identity poses written to the last argument).
"""

from __future__ import annotations

import json
import os
import stat
import sys
from pathlib import Path

TRUTH_NAMES = {"poses.txt", "manifest.json", "degeneracy.csv"}
SKIP = {"/proc", "/sys", "/dev", "/run"}
REPORT_ENV = "SALO_CHEAT_REPORT"  # the test's, not the method's: never searched


def _walk(top: str, depth: int | None, seen: set, found: set, inodes: set | None = None) -> int:
    """Walk ``top`` down ``depth`` levels (None: all); collect truth-named files, or, given ``inodes``, the
    files of those inodes and the truth-named files beside them."""
    examined = 0
    top_depth = top.rstrip(os.sep).count(os.sep)
    for folder, dirs, files in os.walk(top, followlinks=False):
        if folder in SKIP:
            dirs[:] = []
            continue
        if depth is not None and folder.rstrip(os.sep).count(os.sep) - top_depth >= depth:
            dirs[:] = []
        key = (folder, depth)
        if key in seen:
            dirs[:] = []
            continue
        seen.add(key)
        for name in files:
            examined += 1
            path = os.path.join(folder, name)
            if name in TRUTH_NAMES and not inodes:  # the search for other names collects only those
                found.add(path)
            if inodes:
                try:
                    st = os.lstat(path)
                except OSError:
                    continue
                if (st.st_dev, st.st_ino) in inodes:
                    found.add(path)
                    for sibling in os.listdir(folder) if os.path.isdir(folder) else ():
                        if sibling in TRUTH_NAMES:
                            found.add(os.path.join(folder, sibling))
                    parent = os.path.dirname(folder)
                    for sibling in os.listdir(parent) if os.path.isdir(parent) else ():
                        if sibling in TRUTH_NAMES:
                            found.add(os.path.join(parent, sibling))
    return examined


def given_paths(args: list[str], env: dict[str, str], cwd: str) -> tuple[list[str], list[str]]:
    """(folders to search to the bottom, paths to walk up from): the arguments and the working folder, and
    every existing absolute path in the environment."""
    own = [os.path.abspath(a) for a in args if os.path.exists(a) or os.path.exists(os.path.dirname(a) or ".")]
    own.append(cwd)
    from_env = []
    for name, value in env.items():
        if name == REPORT_ENV:
            continue
        for part in value.split(os.pathsep):
            if part.startswith(os.sep) and os.path.exists(part):
                from_env.append(part)
    return own, own + from_env


def search(args: list[str], env: dict[str, str], cwd: str) -> dict:
    """Everything truth-named reachable from ``args``, ``env`` and ``cwd`` (see the module notes)."""
    own, everywhere = given_paths(args, env, cwd)
    found: set[str] = set()
    seen: set = set()
    links, multi = [], []
    examined = 0
    inodes = set()
    for p in own:
        for q in [p, *[str(x) for x in Path(p).rglob("*")]] if os.path.isdir(p) else [p]:
            try:
                st = os.lstat(q)
            except OSError:
                continue
            if stat.S_ISLNK(st.st_mode):
                target = os.path.realpath(q)
                links.append([q, target])
                walk_from = target if os.path.isdir(target) else os.path.dirname(target)
                examined += _walk(os.path.dirname(walk_from), 2, seen, found)
            elif stat.S_ISREG(st.st_mode) and st.st_nlink > 1:
                multi.append([q, st.st_nlink])
                inodes.add((st.st_dev, st.st_ino))
    for p in own:
        if os.path.isdir(p):
            examined += _walk(p, None, seen, found)
    for p in everywhere:
        a = Path(p)
        for ancestor in [a, *a.parents]:
            examined += _walk(str(ancestor), 2, seen, found)
    if inodes:  # another name of a given file exists: search every tree above the given paths for it
        for p in own:
            for ancestor in Path(p).parents:
                if str(ancestor) in (os.sep, *SKIP):
                    continue
                examined += _walk(str(ancestor), None, set(), found, inodes)
    return {"found": sorted(found), "links": links, "hard_links": multi, "examined": examined,
            "searched_from": sorted(set(everywhere))}


def report(result: dict, **more) -> None:
    path = os.environ.get(REPORT_ENV)
    if path:
        with open(path, "a") as fh:
            fh.write(json.dumps({**result, **more}) + "\n")


def main(argv: list[str]) -> int:
    result = search(argv[:-1], dict(os.environ), os.getcwd())
    report(result, kind="command", args=argv)
    n = len([f for f in os.listdir(argv[-2]) if f.endswith(".bin")])  # {scans}, then {out}
    with open(argv[-1], "w") as fh:  # what a cheat that found nothing can give: the identity
        for _ in range(n):
            fh.write("1 0 0 0 0 1 0 0 0 0 1 0\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
