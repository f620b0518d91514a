"""How many commands the gantry takes, per sender and in all (pure; the clock is passed in).

A token bucket per sender (the command's ``operator``: in the secured lab only operators can
send, in the open lab anyone can say any name) and one for all senders together: a sender
may send ``burst`` commands at once and ``per_s`` a second after that; all senders together
``total_burst`` and ``total_per_s``. A stop is never refused (it only makes the crane
safer) but uses up tokens like any command. The first refusal of a sender in a flood is
reported for the log; the rest only counted, until the sender's bucket is full again.
"""

from __future__ import annotations

from dataclasses import dataclass, field

MAX_SENDERS = 256  # names remembered; a flood of new names shares the total bucket anyway


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
    total_per_s: float = 10.0
    total_burst: float = 20.0
    _senders: dict[str, _Bucket] = field(default_factory=dict)
    _total: _Bucket | None = None
    _refused: dict[str, int] = field(default_factory=dict)

    def admit(self, sender: str, now_s: float, always: bool = False) -> Admission:
        """Whether ``sender``'s command is taken now; ``always`` (a stop): taken regardless,
        its tokens spent."""
        if self._total is None:
            self._total = _Bucket(self.total_burst, now_s)
        self._total.refill(now_s, self.total_per_s, self.total_burst)
        if self._total.tokens >= self.total_burst:  # forget the floods that are over
            for name in [n for n in self._refused if self._full(n, now_s)]:
                del self._refused[name]
        bucket = self._bucket(sender, now_s)
        bucket.refill(now_s, self.per_s, self.burst)
        if bucket.tokens >= self.burst:
            self._refused.pop(sender, None)  # its flood, if any, is over
        if always or (bucket.tokens >= 1.0 and self._total.tokens >= 1.0):
            bucket.tokens = max(0.0, bucket.tokens - 1.0)
            self._total.tokens = max(0.0, self._total.tokens - 1.0)
            return Admission(True)
        if sender not in self._refused and len(self._refused) >= MAX_SENDERS:
            return Admission(False)  # a flood of names: logged for the first ones
        count = self._refused[sender] = self._refused.get(sender, 0) + 1
        return Admission(False, report=count == 1, refused_in_flood=count)

    def _full(self, sender: str, now_s: float) -> bool:
        """Whether ``sender``'s bucket is full again by ``now_s`` (its flood is over)."""
        bucket = self._senders.get(sender)
        if bucket is None:
            return True
        bucket.refill(now_s, self.per_s, self.burst)
        return bucket.tokens >= self.burst

    def _bucket(self, sender: str, now_s: float) -> _Bucket:
        bucket = self._senders.get(sender)
        if bucket is None:
            if len(self._senders) >= MAX_SENDERS:  # forget the one heard from longest ago
                del self._senders[min(self._senders, key=lambda k: self._senders[k].at_s)]
            bucket = self._senders[sender] = _Bucket(self.burst, now_s)
        return bucket
