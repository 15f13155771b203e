"""The house's layers, read from the source: no import circle, no import that
runs up the layers, no oversized file (README, "Map of the house").

Every ``import``/``from ... import`` in the package is read with :mod:`ast`,
function-local ones included (a circle hidden inside a function is still a
circle). A module may import its own folder and any folder below it in
``LAYERS``; the folders of one layer may not import each other.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import telethermal

ROOT = Path(telethermal.__file__).parent

#: Bottom to top; one entry per layer, the folders (or top-level modules)
#: that share it. Mirrors the README's map.
LAYERS = [
    {"__init__"},
    {"errors"},
    {"filelimits"},
    {"threads", "tomltables", "npzfile", "jsonfile", "netns", "outputfolder", "cachedir",
     "ports", "choices"},
    {"physics"},
    {"control", "wire"},
    {"devices", "data"},
    {"ident"},
    {"render"},
    {"record"},
    {"teleop"},
    {"sim"},
    {"view"},
    {"services"},
    {"demo"},
    {"bench"},
    {"cli"},
    {"__main__"},
]
MAX_FILE_LINES = 500
MAX_CLI_FUNCTION_LINES = 80


def _unit(module: str) -> str:
    """The folder (or top-level module) a dotted ``telethermal...`` name is in."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _is_module(dotted: str) -> bool:
    path = ROOT.parent.joinpath(*dotted.split("."))
    return path.with_suffix(".py").exists() or (path / "__init__.py").exists()


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, dotted name) of every telethermal module ``path`` imports."""
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            # ``from pkg import name``: a module when ``name`` is one, else ``pkg``.
            targets = [f"{target}.{a.name}" if _is_module(f"{target}.{a.name}") else target
                       for a in node.names]
        elif isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        else:
            continue
        found += [(node.lineno, t) for t in targets if t.split(".")[0] == "telethermal"]
    return found


def _graph() -> dict[str, list[tuple[int, str]]]:
    return {_module_name(p): _imports(p) for p in sorted(ROOT.rglob("*.py"))}


def _layer(unit: str) -> int:
    for i, units in enumerate(LAYERS):
        if unit in units:
            return i
    raise AssertionError(f"telethermal/{unit} is in no layer of tests/unit/test_layers.py: "
                         "place it in LAYERS and in the README's map")


def upward_imports(graph) -> list[str]:
    bad = []
    for module, imports in graph.items():
        here = _unit(module)
        for line, target in imports:
            there = _unit(target)
            if there != here and _layer(there) >= _layer(here):
                bad.append(f"{module}:{line} imports {target} "
                           f"(layer {_layer(there)} from layer {_layer(here)})")
    return bad


def circles(graph) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    modules = set(graph)
    edges = {m: sorted({t for _, t in imps if t in modules and t != m})
             for m, imps in graph.items()}
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def test_no_import_runs_up_the_layers():
    assert upward_imports(_graph()) == []


def test_no_import_circle():
    assert circles(_graph()) == []


#: The product's folders above the simulator's layer: they reach it by name
#: only (``devices/simulated.py``), never by import, so they run without it.
PRODUCT_ABOVE_SIM = {"view", "services"}


def simulator_imports(graph) -> list[str]:
    """Imports of the simulator, the demo or the benches by the product."""
    return [f"{module}:{line} imports {target}"
            for module, imports in graph.items() if _unit(module) in PRODUCT_ABOVE_SIM
            for line, target in imports if _unit(target) in {"sim", "demo", "bench"}]


def test_the_product_does_not_import_the_simulator():
    assert simulator_imports(_graph()) == []
    # The check can fail.
    assert simulator_imports({"telethermal.services.x": [(3, "telethermal.sim.touch")]}) == [
        "telethermal.services.x:3 imports telethermal.sim.touch"]


FIRMWARE = ROOT.parents[1] / "firmware"


def c_graph(folder: Path) -> dict[str, list[tuple[int, str]]]:
    """The firmware's quoted ``#include``s as a graph of units (a ``.c`` and
    its ``.h`` are one unit, named by path without the suffix)."""
    import re

    graph: dict[str, list[tuple[int, str]]] = {}
    for path in sorted(folder.rglob("*.[ch]")):
        unit = str(path.relative_to(folder).with_suffix(""))
        graph.setdefault(unit, [])
        for line, text in enumerate(path.read_text().splitlines(), 1):
            m = re.match(r'\s*#\s*include\s+"([^"]+)"', text)
            if m:
                target = (path.parent / m.group(1)).resolve().relative_to(folder.resolve())
                graph[unit].append((line, str(target.with_suffix(""))))
    return graph


def test_no_include_circle_in_the_firmware():
    # Issue 26: tt_pad.c and tt_peltier.c included each other (for the byte
    # helpers, now in tt_bytes.c).
    graph = c_graph(FIRMWARE)
    assert "src/tt_peltier" in graph and "src/tt_bytes" in graph
    assert circles(graph) == []


def test_the_checks_see_a_circle_and_an_upward_import():
    # The checks themselves, on a made-up graph: they must be able to fail.
    graph = {"telethermal.physics.a": [(1, "telethermal.render.b")],
             "telethermal.render.b": [(1, "telethermal.physics.a")]}
    assert circles(graph) == [["telethermal.physics.a", "telethermal.render.b"]]
    assert upward_imports(graph) == [
        "telethermal.physics.a:1 imports telethermal.render.b (layer 8 from layer 4)"]
    # A relative import is resolved like an absolute one.
    assert _unit("telethermal") == "__init__"


def test_every_folder_has_a_layer():
    for path in ROOT.iterdir():
        if path.is_dir() and (path / "__init__.py").exists():
            _layer(path.name)
        elif path.suffix == ".py":
            _layer(path.stem)


@pytest.mark.parametrize("path", sorted(ROOT.rglob("*.py")), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_source_file_over_500_lines(path):
    n = len(path.read_text().splitlines())
    assert n <= MAX_FILE_LINES, f"{path.relative_to(ROOT)} has {n} lines"


def test_no_command_line_function_over_80_lines():
    cli = ROOT / "cli"
    files = sorted(cli.rglob("*.py")) if cli.is_dir() else [ROOT / "cli.py"]
    long = []
    for path in files:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_CLI_FUNCTION_LINES:
                    long.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name} ({n} lines)")
    assert long == []
