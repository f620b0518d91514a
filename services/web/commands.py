"""The page's gantry buttons: each press is an operator's command on the bus, on the page's
own command key (stb/gantry/command/by/web: the router lets only the page put there), naming
the signed-in user and their address (``alice (web 10.0.0.5)``: the gantry limits the page's
commands per user it names), and the gantry's answer comes back."""

from __future__ import annotations

import itertools
import os
import threading
import time

from common import keys
from common import messages as m
from common.bus import Bus
from common.names import GANTRY_COMMANDS


class GantryCommander:
    def __init__(self, bus: Bus, sender: str, timeout_s: float = 3.0) -> None:
        """``sender``: the page's bus identity (its router user)."""
        self.bus, self.sender, self.timeout_s = bus, sender, timeout_s
        self._replies: dict[str, m.GantryCommandReply] = {}
        self._changed = threading.Condition()
        self._ids = itertools.count()
        bus.subscribe(keys.GANTRY_COMMAND_REPLY, self._on_reply, latest=False)

    def _on_reply(self, reply: m.GantryCommandReply) -> None:
        with self._changed:
            self._replies[reply.id] = reply
            while len(self._replies) > 100:  # only the latest matter
                self._replies.pop(next(iter(self._replies)))
            self._changed.notify_all()

    def send(self, command: str, operator: str) -> dict:
        """Send ``command`` as ``operator`` and wait for the answer: {accepted, detail,
        mode}."""
        if command not in GANTRY_COMMANDS:
            raise ValueError(f"unknown command {command!r}")
        ident = f"web-{os.getpid()}-{next(self._ids)}"
        self.bus.publish(keys.GANTRY_COMMAND, m.GantryCommand(
            measured_s=time.time(), command=command, operator=m.who(operator),
            reason="from the operator page", id=ident), sender=self.sender)
        with self._changed:
            answered = self._changed.wait_for(lambda: ident in self._replies, self.timeout_s)
            reply = self._replies.get(ident)
        if not answered or reply is None:
            return {"accepted": False, "mode": None,
                    "detail": f"no answer from the gantry within {self.timeout_s:g} s"}
        return {"accepted": reply.accepted, "detail": reply.detail, "mode": reply.mode}
