"""The type checker's ground rules (make test runs mypy; pyproject.toml [tool.mypy]): few
``type: ignore`` outside the tests, each naming its error code (mypy itself says whether the
ones in common/ and services/ are needed), and the modules its overrides name exist."""

from __future__ import annotations

import importlib.util
import re
import tomllib

from tests.conftest import ROOT

IGNORE = re.compile(r"#\s*type:\s*ignore(\[[a-z-]+(,\s*[a-z-]+)*\])?")


def _ignores() -> list[tuple[str, str]]:
    found = []
    for folder in ("common", "services", "benchmarks", "compose_test"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            for n, line in enumerate(path.read_text().splitlines(), start=1):
                for match in IGNORE.finditer(line):
                    found.append((f"{path.relative_to(ROOT)}:{n}", match.group(0)))
    return found


def test_at_most_ten_type_ignores_outside_the_tests_each_with_its_code() -> None:
    found = _ignores()
    assert len(found) <= 10, found
    assert [where for where, text in found if "[" not in text] == []


def test_the_strict_modules_and_the_ones_left_out_exist() -> None:
    """Every module an override names (the strict ones, the ones left unchecked) exists, and
    there are strict ones."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["mypy"]
    overrides = config["overrides"]
    assert [o for o in overrides if o.get("disallow_untyped_defs")], "the strict modules"
    for module in (m for override in overrides for m in override["module"]):
        if module.endswith(".*"):
            assert (ROOT / module[:-2].replace(".", "/")).is_dir(), module
        else:
            assert importlib.util.find_spec(module) is not None, module
