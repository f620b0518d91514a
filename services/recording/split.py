"""When ``stb record`` starts a new file (pure): ``--split-size`` / ``--split-time``. Each part
is a complete MCAP file named after the one asked for with its number: ``run.mcap`` →
``run-001.mcap``, ``run-002.mcap``, … (``stb report`` and ``stb replay`` take them as one run)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class SplitRule:
    """A new part once the current one holds ``max_bytes`` or spans ``max_s`` of receive time
    (None: no limit of that kind)."""

    max_bytes: int | None = None
    max_s: float | None = None

    @property
    def splits(self) -> bool:
        return self.max_bytes is not None or self.max_s is not None

    def due(self, size_bytes: int, started_s: float, now_s: float) -> bool:
        """Whether the part that began at ``started_s`` and holds ``size_bytes`` is full."""
        return (self.max_bytes is not None and size_bytes >= self.max_bytes) or \
            (self.max_s is not None and now_s - started_s >= self.max_s)


def part_path(out: Path, number: int) -> Path:
    """Part ``number`` (1, 2, …) of the recording asked for as ``out``."""
    return out.with_name(f"{out.stem}-{number:03d}{out.suffix or '.mcap'}")
