"""How many commands the gantry takes from each sender (pure; the clock is passed in).

A token bucket per sender: a sender may send ``burst`` commands at once and ``per_s`` a second
after that; the rest are refused. A sender is who really sent the command — its bus identity,
which the router's access control checks (each identity may put only on its own command key),
or for an identity that signs in its own users (the page) the user it names — never a name a
sender writes into its command: a flood under a thousand names from one identity is one
sender's flood, and no sender's flood spends another's tokens. A stop is never refused (it
only makes the crane safer) but uses up tokens like any command. The first refusal of a
sender in a flood is reported for the log; the rest only counted, until the sender's bucket
is full again.
"""

from __future__ import annotations

from dataclasses import dataclass, field

MAX_SENDERS = 256
"""Senders remembered; past that the one heard from longest ago is forgotten (on a secured bus
the router admits a handful of identities; only an open bus lets anyone name a new one)."""


@dataclass
class _Bucket:
    tokens: float
    at_s: float

    def refill(self, now_s: float, per_s: float, burst: float) -> None:
        self.tokens = min(burst, self.tokens + max(0.0, now_s - self.at_s) * per_s)
        self.at_s = now_s


@dataclass(frozen=True)
class Admission:
    admitted: bool
    report: bool = False  # the first refusal of this sender's flood: log it
    refused_in_flood: int = 0  # refusals of this sender since its flood began


@dataclass
class CommandRate:
    per_s: float = 2.0
    burst: float = 5.0
    _senders: dict[str, _Bucket] = field(default_factory=dict)
    _refused: dict[str, int] = field(default_factory=dict)

    def admit(self, sender: str, now_s: float, always: bool = False) -> Admission:
        """Whether ``sender``'s command is taken now; ``always`` (a stop): taken regardless,
        its tokens spent."""
        bucket = self._bucket(sender, now_s)
        bucket.refill(now_s, self.per_s, self.burst)
        if bucket.tokens >= self.burst:
            self._refused.pop(sender, None)  # its flood, if any, is over
        if always or bucket.tokens >= 1.0:
            bucket.tokens = max(0.0, bucket.tokens - 1.0)
            return Admission(True)
        count = self._refused[sender] = self._refused.get(sender, 0) + 1
        return Admission(False, report=count == 1, refused_in_flood=count)

    def _bucket(self, sender: str, now_s: float) -> _Bucket:
        bucket = self._senders.get(sender)
        if bucket is None:
            if len(self._senders) >= MAX_SENDERS:  # forget the one heard from longest ago
                oldest = min(self._senders, key=lambda k: self._senders[k].at_s)
                del self._senders[oldest]
                self._refused.pop(oldest, None)
            bucket = self._senders[sender] = _Bucket(self.burst, now_s)
        return bucket
