"""Where a PTZ service's camera pose comes from (pure; every clock is an argument): the
calibration service's answer to the service's own query of its pose key — never a message put
on that key, which anyone on an open bus could send (a pose at version 2⁵³ once mis-aimed a
camera for good). A message on the key only makes it ask sooner.

It asks at start, soon after a pose is heard on the key (at most every ``heard_min_s``), every
``every_s`` in any case, and every ``doubt_every_s`` while the camera's own pictures disagree
with the pose (the pointing check). Answers that disagree with each other (a second queryable
on the key) are none: the camera keeps the pose it has and says why.
"""

from __future__ import annotations

from dataclasses import dataclass

from common import messages as m


def _solve(pose: m.CameraPose) -> str:
    """What a pose says (its lens included), comparable between answers."""
    return pose.model_dump_json(exclude={"sent_s"})


def choose(answers: list[m.CameraPose], camera: str) -> tuple[m.CameraPose | None, str]:
    """The pose the answers agree on, or None and why not."""
    if not answers:
        return None, f"the calibration service did not answer for {camera}"
    distinct = {_solve(a) for a in answers}
    if len(distinct) > 1:
        return None, (f"{len(distinct)} different poses answered for {camera}: another "
                      "queryable on its key? the camera keeps the pose it has")
    return answers[0], ""


@dataclass
class PoseAsking:
    every_s: float = 30.0
    heard_min_s: float = 0.5
    doubt_every_s: float = 5.0
    asked_s: float | None = None
    _heard: bool = True  # at start: ask at once

    def heard(self) -> None:
        """A pose was put on the key: ask the calibration service soon."""
        self._heard = True

    def due(self, now: float, doubting: bool) -> bool:
        if self.asked_s is None:
            return True
        since = now - self.asked_s
        return ((self._heard and since >= self.heard_min_s) or since >= self.every_s
                or (doubting and since >= self.doubt_every_s))

    def asked(self, now: float) -> None:
        self.asked_s, self._heard = now, False
