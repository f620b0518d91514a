"""The doctor's verdicts (pure): one row per check — what was found, and the fix when it
failed — as a text table, JSON and an exit status."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Literal

Verdict = Literal["pass", "fail", "skip"]
MARK = {"pass": "ok", "fail": "FAIL", "skip": "skip"}


@dataclass(frozen=True)
class Check:
    """One check: ``found`` says what was measured; ``fix`` what to do (failed rows)."""

    name: str
    verdict: Verdict
    found: str
    fix: str = ""

    def as_dict(self) -> dict[str, str]:
        return asdict(self)


def passed(name: str, found: str) -> Check:
    return Check(name, "pass", found)


def failed(name: str, found: str, fix: str) -> Check:
    return Check(name, "fail", found, fix)


def skipped(name: str, why: str) -> Check:
    return Check(name, "skip", why)


def exit_status(checks: list[Check]) -> int:
    """0 when no check failed, 1 otherwise (a skipped check does not apply to this lab)."""
    return 1 if any(c.verdict == "fail" for c in checks) else 0


def render(checks: list[Check], width: int = 100) -> str:
    """The table: name, verdict, what was found; a failed row's fix on the line below."""
    name_w = max([len(c.name) for c in checks] + [5])
    lines = [f"{'check':<{name_w}}  {'':4}  found", "-" * min(width, name_w + 60)]
    for c in checks:
        lines.append(f"{c.name:<{name_w}}  {MARK[c.verdict]:<4}  {c.found}")
        if c.fix:
            lines.append(f"{'':<{name_w}}  {'':4}  fix: {c.fix}")
    failures = sum(c.verdict == "fail" for c in checks)
    lines.append("")
    lines.append("all checks passed" if not failures else
                 f"{failures} of {len(checks)} checks failed")
    return "\n".join(lines)
