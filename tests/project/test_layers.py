"""The harness's layers (docs/architecture.md): each module uses only its own layer and
the layers below, there is no import circle among the harness's modules (imports inside
functions counted), and the physics never imports the harness."""
import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
HARNESS = ROOT / "harness"
ARCHITECTURE = ROOT / "docs" / "architecture.md"


def modules() -> dict[str, Path]:
    out = {}
    for path in HARNESS.rglob("*.py"):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


def imported(module: str, path: Path, known: dict) -> set[str]:
    """The harness modules ``module`` imports anywhere in its text (in functions too):
    ``from a import b`` is a use of module ``a.b`` when that is one, else of ``a``."""
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name in known)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package[:len(package) - node.level + 1] + ([node.module] if node.module else []))
            for alias in node.names:
                target = f"{base}.{alias.name}"
                out.add(target if target in known else base)
    return {m for m in out if m in known and m != module}


def graph() -> dict[str, set[str]]:
    known = modules()
    return {m: imported(m, p, known) for m, p in known.items()}


def circles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan), and self-loops."""
    index, low, stack, on, found = {}, {}, [], set(), []

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
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def layer_table() -> list[tuple[str, list[str]]]:
    """The layers as docs/architecture.md writes them, bottom first: the rows of its
    table between the ``<!-- layers -->`` markers, ``| n | name | packages |``."""
    text = ARCHITECTURE.read_text()
    block = re.search(r"<!-- layers -->(.*?)<!-- /layers -->", text, re.S)
    assert block, f"{ARCHITECTURE}: no <!-- layers --> ... <!-- /layers --> table"
    rows = []
    for line in block.group(1).splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) >= 3 and cells[0].isdigit():
            assert int(cells[0]) == len(rows), f"{ARCHITECTURE}: layer row numbered {cells[0]} where {len(rows)} is next"
            rows.append((cells[1], re.findall(r"`([\w.]+)`", cells[2])))
    names = [name for name, _ in rows]
    assert len(set(names)) == len(names), f"{ARCHITECTURE}: a layer written twice: {names}"
    return rows


def layer_of(module: str, table) -> int:
    """The layer of ``module``: the row naming it or the package that holds it (the
    top package ``harness`` names itself only: a new module directly in it needs a row)."""
    best = None
    for level, (_, prefixes) in enumerate(table):
        for prefix in prefixes:
            if module == prefix or (prefix != "harness" and module.startswith(prefix + ".")):
                if best is None or len(prefix) > best[1]:
                    best = (level, len(prefix))
    assert best is not None, f"{module} is in no layer of docs/architecture.md: give it a place there"
    return best[0]


def test_no_import_circle_among_harness_modules():
    assert circles(graph()) == []


def test_the_circle_finder_finds_circles():
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert circles({"a": {"b"}, "b": set()}) == []


def test_every_module_uses_only_its_layer_and_those_below():
    table = layer_table()
    assert [name for name, _ in table][:2] == ["base", "description"] and table[-1][0] == "cli"
    edges = graph()
    upward = [f"{m} (layer {table[layer_of(m, table)][0]}) imports {t} (layer {table[layer_of(t, table)][0]})"
              for m, targets in sorted(edges.items()) for t in sorted(targets)
              if layer_of(t, table) > layer_of(m, table)]
    assert upward == []


def test_the_layer_check_sees_an_upward_use():
    table = layer_table()
    assert layer_of("harness.description.scene", table) < layer_of("harness.formats.ssp", table)
    assert layer_of("harness.engine.masters.base", table) == layer_of("harness.engine.run", table)
    # the Python API sits on the studies and under the command line, which calls it
    assert layer_of("harness.studies.bench", table) < layer_of("harness.api", table) < layer_of("harness.cli", table)
    with pytest.raises(AssertionError, match="in no layer"):
        layer_of("harness.new_module", table)


def test_the_physics_never_imports_the_harness():
    offenders = [str(p.relative_to(ROOT)) for p in (ROOT / "fmu_src").rglob("*.py")
                 if re.search(r"^\s*(from|import)\s+harness\b", p.read_text(), re.M)]
    assert offenders == []


def test_the_cli_has_every_command_and_no_other_name():
    from harness.cli import main

    assert set(main.commands) == {"badinputs", "bench", "build", "cache", "compliance", "engines", "export-container",
                                  "export-ssp", "fingerprint", "hosts", "measured", "reference", "run", "scenes",
                                  "stability", "study", "sweep", "validate"}


def test_the_command_line_reaches_the_layers_through_the_api_only():
    """A command parses, calls ``harness.api`` and prints: what it runs is there for a
    Python user too, and a change below the api does not reach into the command line."""
    edges = graph()
    allowed = {"harness.api", "harness.api.inputs", "harness.paths"}   # api.inputs: what the api's arguments accept
    offenders = {m: sorted(u for u in uses if u not in allowed and not u.startswith("harness.cli"))
                 for m, uses in edges.items() if m == "harness.cli" or m.startswith("harness.cli.")}
    assert len(offenders) > 1 and {m: u for m, u in offenders.items() if u} == {}


def test_no_private_name_is_used_outside_its_module():
    """``from harness.x import _y`` and ``x._y`` (x a harness module) in harness code."""
    offenders = []
    for module, path in modules().items():
        tree = ast.parse(path.read_text())
        harness_names = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.level or (node.module or "").startswith("harness")):
                for alias in node.names:
                    if alias.name.startswith("_") and not alias.name.startswith("__"):
                        offenders.append(f"{module} imports {node.module}.{alias.name}")
                    harness_names.add(alias.asname or alias.name)
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in harness_names
                    and node.attr.startswith("_") and not node.attr.startswith("__")):
                offenders.append(f"{module} uses {node.value.id}.{node.attr}")
    assert offenders == []

