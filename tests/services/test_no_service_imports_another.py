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
