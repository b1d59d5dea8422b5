"""The import graph of the project follows ARCHITECTURE.md's rules.

Every module of ``simlidar``, ``scenes``, ``odometry`` and ``tools`` is parsed
with ``ast`` (imports inside functions count: they are cycles and dependencies
too, only later), relative imports are resolved, and each import is mapped to
the project module it loads (``from pkg import name`` is the module
``pkg.name`` when there is one, else ``pkg``). Then:

(a) no module outside the command line (``tools.cli``) imports a module of it;
(b) there are no cycles among the project's modules;
(c) the package rules: ``odometry`` imports only Embree-free ``simlidar``
    modules (no ``embreex`` among everything they import, transitively) and no
    plotting code, and never ``scenes`` or ``tools``; ``scenes`` and ``simlidar``
    import neither each other nor ``tools``; nothing imports ``tools`` but ``tools``;
    ``paramspec`` (which every package may import) imports no project module and
    nothing outside the standard library;
(d) the experiments are the top of ``tools``: only they and the command line
    import ``tools.experiments`` (they import the methods, the peers and what
    ``tools`` shares, never the reverse);
(e) no module imports another's private name (``from X import _name``): what
    several modules use is a public name of a module named for its idea.

The checks are functions of a graph, so the synthetic graphs at the end show
that each of them can fail.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("paramspec", "simlidar", "scenes", "odometry", "tools")
CLI = "tools.cli"
EXPERIMENTS = "tools.experiments"
EMBREE = "embreex"
PLOTTING = ("matplotlib", "pyvista", "vtk", "vtkmodules")


# ---------------------------------------------------------------- building the graph
def module_files(root: Path = REPO, packages: tuple[str, ...] = PACKAGES) -> dict[str, Path]:
    """Dotted module name -> file, for every .py of the packages (a package is its ``__init__``)."""
    out = {}
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


def resolve(dotted: str, modules: set[str]) -> str | None:
    """The project module a dotted import name loads: the longest prefix that is a module, or None."""
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        candidate = ".".join(parts[:k])
        if candidate in modules:
            return candidate
    return None


def imports_of(name: str, path: Path, modules: set[str]) -> tuple[set[str], set[str]]:
    """(project modules, external top-level packages) that module ``name`` imports, anywhere in it.

    ``from pkg import x`` is the module ``pkg.x`` when there is one (a submodule),
    else ``pkg`` itself (a name out of it); relative imports are made absolute.
    """
    tree = ast.parse(path.read_text(), str(path))
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    project, external = set(), set()

    def add(dotted: str) -> None:
        target = resolve(dotted, modules)
        if target is None:
            external.add(dotted.split(".")[0])
        elif target != name:
            project.add(target)

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                add(alias.name)
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            module = ".".join(base + ([node.module] if node.module else []))
            for alias in node.names:
                sub = f"{module}.{alias.name}"
                add(sub if sub in modules else module)
    return project, external


def private_imports(name: str, path: Path, modules: set[str]) -> list[str]:
    """``from X import _name`` in module ``name`` (anywhere in it) where X is another project module:
    "name imports _name from X" for each (a module's own names, and dunders, are not counted)."""
    tree = ast.parse(path.read_text(), str(path))
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            source = resolve(".".join(base + ([node.module] if node.module else [])), modules)
            for alias in node.names:
                private = alias.name.startswith("_") and not alias.name.startswith("__")
                if private and source is not None and source != name:
                    found.append(f"{name} imports {alias.name} from {source}")
    return found


def build_graph(files: dict[str, Path]) -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    """(project module -> project modules it imports, project module -> external packages it imports)."""
    modules = set(files)
    graph, external = {}, {}
    for name, path in files.items():
        graph[name], external[name] = imports_of(name, path, modules)
    return graph, external


# ---------------------------------------------------------------- the rules
def package_of(module: str) -> str:
    return module.split(".")[0]


def is_cli(module: str) -> bool:
    return module == CLI or module.startswith(CLI + ".")


def cli_violations(graph: dict[str, set[str]]) -> list[str]:
    """(a) imports of a command-line module from outside the command line."""
    return [f"{src} imports the command-line module {dst}" for src, dsts in sorted(graph.items())
            for dst in sorted(dsts) if is_cli(dst) and not is_cli(src)]


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """(b) the strongly connected components of more than one module (Tarjan), each as a sorted list."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1 or v in graph.get(v, ()):
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def reachable(graph: dict[str, set[str]], start: str) -> set[str]:
    """Every module ``start`` imports, directly or not (``start`` included)."""
    seen, todo = {start}, [start]
    while todo:
        for w in graph.get(todo.pop(), ()):
            if w not in seen:
                seen.add(w)
                todo.append(w)
    return seen


def package_violations(graph: dict[str, set[str]], external: dict[str, set[str]]) -> list[str]:
    """(c) the package rules of ARCHITECTURE.md."""
    forbidden = {"odometry": {"scenes", "tools"}, "scenes": {"simlidar", "tools"}, "simlidar": {"scenes", "tools"},
                 "paramspec": {"simlidar", "scenes", "odometry", "tools"}}
    out = []
    for src, dsts in sorted(graph.items()):
        pkg = package_of(src)
        for dst in sorted(dsts):
            if package_of(dst) in forbidden.get(pkg, ()):
                out.append(f"{src} imports {dst}: {pkg} may not import {package_of(dst)}")
            if pkg == "odometry" and package_of(dst) == "simlidar":
                loads = {m for m in reachable(graph, dst) if EMBREE in external.get(m, ())}
                if loads:
                    out.append(f"{src} imports {dst}, which loads Embree (through {', '.join(sorted(loads))})")
        if pkg == "paramspec":
            outside = sorted(e for e in external.get(src, ()) if e not in sys.stdlib_module_names)
            if outside:
                out.append(f"{src} imports {', '.join(outside)}: paramspec uses the standard library only")
        if pkg == "odometry":
            plotting = {m for m in reachable(graph, src)
                        if any(p in external.get(m, ()) for p in PLOTTING)}
            if plotting:
                out.append(f"{src} loads plotting code (through {', '.join(sorted(plotting))})")
    return out


def experiment_violations(graph: dict[str, set[str]]) -> list[str]:
    """(d) imports of ``tools.experiments`` from outside it and the command line."""
    def inside(module: str) -> bool:
        return module == EXPERIMENTS or module.startswith(EXPERIMENTS + ".")

    return [f"{src} imports the experiment module {dst}" for src, dsts in sorted(graph.items())
            for dst in sorted(dsts) if inside(dst) and not inside(src) and not is_cli(src)]


# ---------------------------------------------------------------- the project
FILES = module_files()
GRAPH, EXTERNAL = build_graph(FILES)


def test_the_graph_covers_the_project():
    assert len(GRAPH) > 80 and {"simlidar.dataset", "odometry.pipeline", "tools.cli", "tools.cli.common",
                                "paramspec.declare"} <= set(GRAPH)
    # relative imports resolved, in-function imports seen, `from pkg import submodule` as the submodule
    assert "simlidar.formats.kitti" in GRAPH["simlidar.formats.salo"]  # from .kitti import ...
    assert "simlidar.formats.rosbag" in GRAPH["simlidar.dataset"]  # from .formats import rosbag
    assert "tools.runners" in GRAPH["tools.cli.odometry"]  # inside cmd_odometry
    assert "tools.cli.common" in GRAPH["tools.cli.scenes"]  # from .common import ...
    assert EMBREE in EXTERNAL["simlidar.raycast"]


def test_nothing_outside_the_command_line_imports_it():
    assert cli_violations(GRAPH) == []


def test_no_import_cycles_not_even_inside_functions():
    assert cycles(GRAPH) == []


def test_package_rules_of_the_architecture():
    assert package_violations(GRAPH, EXTERNAL) == []


def test_only_the_experiments_and_the_command_line_import_the_experiments():
    assert experiment_violations(GRAPH) == []


def test_no_module_imports_another_modules_private_names():
    assert [v for name, path in FILES.items() for v in private_imports(name, path, set(FILES))] == []


def test_odometry_imports_simlidar_without_embree():
    used = {dst for src, dsts in GRAPH.items() if src.startswith("odometry") for dst in dsts
            if dst.startswith("simlidar")}
    assert used and all(EMBREE not in EXTERNAL[m] for d in used for m in reachable(GRAPH, d))


# ---------------------------------------------------------------- the checks can fail
def test_the_checks_catch_synthetic_violations():
    graph = {
        "tools.sweep.tasks": {"tools.cli.common"},  # library -> command line
        "tools.cli.common": set(),
        "simlidar.a": {"simlidar.b"}, "simlidar.b": {"simlidar.c"}, "simlidar.c": {"simlidar.a"},  # a cycle
        "simlidar.d": {"tools.x", "scenes.y"}, "tools.x": set(), "scenes.y": {"simlidar.d"},  # package rules
        "odometry.p": {"simlidar.e"}, "simlidar.e": {"simlidar.raycast"}, "simlidar.raycast": set(),
        "odometry.q": {"odometry.plots"}, "odometry.plots": set(),
        "paramspec.x": {"scenes.y"},
        "tools.methods": {"tools.experiments.peer"}, "tools.experiments.peer": set(),  # the reverse layering
        "tools.experiments.table": {"tools.methods"}, "tools.cli.experiment": {"tools.experiments.table"},
    }
    external = {"simlidar.raycast": {EMBREE}, "odometry.plots": {"matplotlib"}, "paramspec.x": {"numpy", "math"}}
    assert cli_violations(graph) == ["tools.sweep.tasks imports the command-line module tools.cli.common"]
    assert sorted(cycles(graph)) == [["scenes.y", "simlidar.d"], ["simlidar.a", "simlidar.b", "simlidar.c"]]
    found = package_violations(graph, external)
    assert any("simlidar.d imports tools.x" in f for f in found)
    assert any("simlidar.d imports scenes.y" in f for f in found)
    assert any("scenes.y imports simlidar.d" in f for f in found)
    assert any("odometry.p imports simlidar.e, which loads Embree (through simlidar.raycast)" in f for f in found)
    assert any("odometry.q loads plotting code (through odometry.plots)" in f for f in found)
    assert any("paramspec.x imports scenes.y: paramspec may not import scenes" in f for f in found)
    assert any("paramspec.x imports numpy: paramspec uses the standard library only" in f for f in found)
    assert experiment_violations(graph) == ["tools.methods imports the experiment module tools.experiments.peer"]


def write_package(root: Path, sources: dict[str, str]) -> None:
    """A synthetic package under ``root``: relative path -> source."""
    for relative, text in sources.items():
        (root / relative).parent.mkdir(parents=True, exist_ok=True)
        (root / relative).write_text(text)


def test_the_private_import_check_catches_one(tmp_path):
    write_package(tmp_path, {
        "tools/__init__.py": "", "tools/sub/__init__.py": "",
        "tools/sub/plots.py": "def _figure():\n    pass\n\ndef save():\n    _figure()\n",
        "tools/sub/page.py": "from .plots import save\n\ndef draw():\n    from .plots import _figure\n",
        "tools/other.py": "from tools.sub.plots import _figure, save\nfrom .sub import plots as __x\n",
    })
    files = module_files(tmp_path, ("tools",))
    found = [v for name, path in files.items() for v in private_imports(name, path, set(files))]
    assert found == ["tools.other imports _figure from tools.sub.plots",
                     "tools.sub.page imports _figure from tools.sub.plots"]


def test_relative_and_in_function_imports_are_resolved(tmp_path):
    write_package(tmp_path, {
        "simlidar/__init__.py": "", "simlidar/sub/__init__.py": "from . import leaf\n",
        "simlidar/sub/leaf.py": "def f():\n    from ..top import x\n    return x\n",
        "simlidar/top.py": "from .sub.leaf import f\n",
    })
    graph, _ = build_graph(module_files(tmp_path, ("simlidar",)))
    assert graph["simlidar.sub"] == {"simlidar.sub.leaf"}
    assert graph["simlidar.sub.leaf"] == {"simlidar.top"}
    assert graph["simlidar.top"] == {"simlidar.sub.leaf"}
    assert cycles(graph) == [["simlidar.sub.leaf", "simlidar.top"]]
