"""docs/architecture.md names files and what is in them: every file it names is there, and
every ``file.py`` ``Name`` pair it gives names something that file defines."""

from __future__ import annotations

import re

from tests.conftest import ROOT

PAGE = (ROOT / "docs" / "architecture.md").read_text()
PATH = re.compile(r"`((?:common|services|benchmarks|deploy|tests)/[\w/.-]+\.(?:py|json5|md))`")
BARE = re.compile(r"`([a-z_]+\.py)`")
PAIR = re.compile(r"`((?:common/|services/[\w/]+/)?[a-z_]+\.py)` `([A-Za-z_]\w*)`")


def test_every_file_it_names_is_there() -> None:
    missing = [p for p in PATH.findall(PAGE) if not (ROOT / p).exists()]
    assert missing == []
    known = {p.name for p in ROOT.glob("**/*.py") if ".venv" not in p.parts}
    assert [name for name in BARE.findall(PAGE) if name not in known] == []


def test_every_name_it_gives_a_file_is_defined_there() -> None:
    pairs = PAIR.findall(PAGE)
    assert len(pairs) >= 10, "the page names what the paths pass through"
    wrong = []
    for path, name in pairs:  # a bare file name: any file of that name in the project
        files = [ROOT / path] if "/" in path else [
            f for f in ROOT.glob(f"[cs]*/**/{path}") if ".venv" not in f.parts]
        if not any(re.search(rf"^\s*(class|def) {name}\b|^{name}\b.*=", f.read_text(),
                             re.MULTILINE) for f in files):
            wrong.append(f"{path} {name}")
    assert wrong == []
