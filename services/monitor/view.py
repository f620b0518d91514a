"""What the monitor shows, as pure functions of what it has received (no I/O, no clock)."""

from __future__ import annotations

import json
from collections import deque
from dataclasses import dataclass, field

from pydantic import BaseModel

from common import codec

RATE_WINDOW_S = 5.0


def json_line(key: str, msg: BaseModel | dict) -> str:
    """One ``--raw`` output line: the key, the model name and every field."""
    kind = type(msg).__name__ if isinstance(msg, BaseModel) else "msgpack"
    return json.dumps({"key": key, "type": kind, **codec.to_plain(msg)}, allow_nan=False)


def summary(msg: BaseModel | dict, width: int = 60) -> str:
    """A short one-line digest of a message for the table."""
    parts = []
    data = msg.model_dump() if isinstance(msg, BaseModel) else dict(msg)
    for name, value in data.items():
        if name in ("measured_s", "sent_s"):
            continue
        if isinstance(value, bytes):  # frames: say how big, do not encode them every redraw
            value = f"<{len(value)} bytes>"
        elif isinstance(value, float):
            value = f"{value:.1f}"
        elif isinstance(value, list):
            value = f"[{len(value)}]"
        elif isinstance(value, dict):
            value = f"{{{len(value)}}}"
        elif isinstance(value, str) and len(value) > 16:
            value = f"<{len(value)} chars>"
        parts.append(f"{name}={value}")
    return _fit(" ".join(parts), width)


@dataclass
class KeyView:
    latest: BaseModel | dict
    received_s: deque[float] = field(default_factory=deque)

    def add(self, msg: BaseModel | dict, now_s: float) -> None:
        self.latest = msg
        self.received_s.append(now_s)
        while self.received_s and now_s - self.received_s[0] > RATE_WINDOW_S:
            self.received_s.popleft()

    def rate_hz(self, now_s: float) -> float:
        recent = [t for t in self.received_s if now_s - t <= RATE_WINDOW_S]
        if len(recent) < 2:
            return 0.0
        return (len(recent) - 1) / max(recent[-1] - recent[0], 1e-9)

    def age_s(self, now_s: float) -> float:
        return now_s - self.received_s[-1] if self.received_s else float("inf")


@dataclass
class LabView:
    """Everything the monitor knows: alive services and the latest sample of every key."""

    alive: set[tuple[str, str]] = field(default_factory=set)
    keys: dict[str, KeyView] = field(default_factory=dict)

    def on_sample(self, key: str, msg: BaseModel | dict, now_s: float) -> None:
        view = self.keys.get(key)
        if view is None:
            self.keys[key] = view = KeyView(msg)
        view.add(msg, now_s)

    def on_alive(self, service: str, instance: str, alive: bool) -> None:
        (self.alive.add if alive else self.alive.discard)((service, instance))

    def render(self, now_s: float, width: int = 120, height: int | None = None) -> str:
        """The table for a terminal of ``width`` × ``height`` (None: as long as it takes):
        nothing wraps — the digest of the latest sample narrows, then goes, before the rates
        do, keys are cut with "…", and what does not fit is counted in the last line."""
        alive = " ".join(f"{s}/{i}" for s, i in sorted(self.alive)) or "(none)"
        lines = [_fit(f"alive ({len(self.alive)}): {alive}", width), ""]
        longest = max((len(k) for k in self.keys), default=3)
        key_w = min(longest, max(24, width - 19 - 30))  # 30 left for the digest, if it can
        digest_w = width - key_w - 21
        head = f"{'key':<{key_w}} {'rate Hz':>8} {'age s':>7}"
        lines.append(head + ("  latest" if digest_w >= 16 else ""))
        rows = []
        for key in sorted(self.keys):
            view = self.keys[key]
            row = f"{_fit(key, key_w):<{key_w}} {view.rate_hz(now_s):8.1f} {view.age_s(now_s):7.1f}"
            if digest_w >= 16:
                row += f"  {summary(view.latest, digest_w)}"
            rows.append(_fit(row, width))
        if not self.keys:
            rows.append("(no samples yet)")
        room = None if height is None else max(1, height - len(lines) - 1)
        if room is not None and len(rows) > room:
            rows = rows[:room - 1] + [f"… {len(rows) - room + 1} more keys"]
        return "\n".join(lines + rows)


def _fit(text: str, width: int) -> str:
    return text if len(text) <= width else text[:max(width - 1, 0)] + "…"
