"""No service imports another: what two share lives in ``common/``.

What a tool reads of another service's lab-file section is a view in ``common/lab_views.py``,
or the whole section's model in ``common/`` (``stb deploy render`` checks all of ``[ptz]``:
``common/ptz_settings.py``). One import across packages is by design and named here: the
experiment harness runs the live gantry against the sim (docs/experiments.md), so it imports
both.
"""

from __future__ import annotations

import ast
from pathlib import Path

SERVICES = Path(__file__).resolve().parents[2] / "services"
BY_DESIGN = {"experiment": {"services.gantry", "services.sim"}}


def _imported(path: Path) -> list[tuple[int, str]]:
    """(line, module) of every import in a file, at any depth (functions import lazily)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.append((node.lineno, node.module))
    return found


def crossings() -> list[str]:
    packages = {p.name for p in SERVICES.iterdir() if (p / "__init__.py").is_file()}
    out = []
    for package in sorted(packages):
        for path in sorted((SERVICES / package).rglob("*.py")):
            for line, module in _imported(path):
                parts = module.split(".")
                if parts[0] != "services" or len(parts) < 2 or parts[1] not in packages:
                    continue
                other = parts[1]
                allowed = BY_DESIGN.get(package, set())
                if other == package or any(module == a or module.startswith(a + ".")
                                           for a in allowed):
                    continue
                out.append(f"{path.relative_to(SERVICES.parent)}:{line} imports {module}")
    return out


def test_no_service_imports_another() -> None:
    assert crossings() == []


def test_the_check_sees_an_import_inside_a_function(tmp_path: Path) -> None:
    module = tmp_path / "m.py"
    module.write_text("def f():\n    from services.ptz.aim import aim_at\n")
    assert _imported(module) == [(2, "services.ptz.aim")]


# --- no import circle --------------------------------------------------------------------------

ROOT = SERVICES.parent


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted([*ROOT.glob("common/**/*.py"), *SERVICES.glob("**/*.py")]):
        name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
        out[name.removesuffix(".__init__")] = path
    return out


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import circles of ``graph`` (module → the modules it imports): each strongly
    connected group of more than one module, or a module that imports itself."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(module: str) -> None:  # Tarjan's
        index[module] = low[module] = len(index)
        stack.append(module)
        for other in sorted(graph.get(module, ())):
            if other not in index:
                visit(other)
                low[module] = min(low[module], low[other])
            elif other in stack:
                low[module] = min(low[module], index[other])
        if low[module] == index[module]:
            group = stack[stack.index(module):]
            del stack[stack.index(module):]
            if len(group) > 1 or module in graph.get(module, ()):
                found.append(sorted(group))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return found


def import_graph() -> dict[str, set[str]]:
    """Every import at any depth (a lazy import in a function closes a circle as well, when
    it runs), of a module or of a module's name (``from services.calib import solve``)."""
    modules = _modules()
    graph = {}
    for name, path in modules.items():
        targets = set()
        for _, module in _imported(path):
            if module in modules:
                targets.add(module)
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets |= {f"{node.module}.{a.name}" for a in node.names} & modules.keys()
        graph[name] = targets - {name}
    return graph


def test_no_import_circle() -> None:
    assert circles(import_graph()) == []


def test_the_circle_check_finds_one() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert circles(graph) == [["a", "b", "c"]]
