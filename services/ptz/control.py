"""What a PTZ service decides, without I/O or a clock of its own (pure).

Which camera pose holds (the calibration service's answer to this service's query, never
one measured in the future: ``pose_source.py``), whether a robot sample moves the camera
(a pose and the camera's limits known, the camera not failing, not held for calibration, not
in someone else's hands) and where to, how long to wait after the camera failed (doubling up
to ``RETRY_MAX_S``), and what the camera's status is. ``services/ptz/service.py`` wires it to
the bus and the camera; calibration mode (``calibration.py``) and previews (``preview.py``)
are drivers beside it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from common import messages as m
from common.backoff import doubled
from common.camera import Pose, PtzLimits
from common.ptz_lens import PtzLens, lens_of, straight_line
from services.ptz.aim import aim_error_deg
from services.ptz.follow import Command, Follower
from services.ptz.override import ManualOverride
from services.ptz.pointing import NOT_SEEN, InfraredSchedule, PointingCheck

log = logging.getLogger(__name__)
HAND_MAX_AGE_S = 5.0  # an operator's hand older than this was meant for another moment
HAND_MOVES = ("move", "nudge", "preset")  # the hands that move the camera
RETRY_FIRST_S = 0.5
RETRY_MAX_S = 5.0


@dataclass(frozen=True)
class Status:
    """The camera's state as published: status, aim error and the pointing check."""

    status: m.PtzStatus
    aim_error_deg: float
    pointing_error_deg: float | None
    problem: str  # "" when the pointing check is content
    health: m.HealthStatus
    health_why: str


@dataclass
class PtzControl:
    follower: Follower
    override: ManualOverride
    pointing: PointingCheck
    name: str = "ptz"
    max_future_s: float = 1.0
    infrared: InfraredSchedule = field(default_factory=lambda: InfraredSchedule(0.0, 0.0))
    pose_msg: m.CameraPose | None = None
    pose: Pose | None = None  # converted once, when it arrives (robot samples come at 1 kHz)
    robot: m.RobotPosition | None = None
    limits: PtzLimits | None = None
    retry_at: float = 0.0
    retry_s: float = RETRY_FIRST_S
    manual: bool = False  # following paused for someone else's move
    held_by: str = ""  # an operator holds the camera (the page): it does not follow
    pose_problem: str = ""  # the calibration service's answers disagreed, or none came

    @property
    def lens(self) -> PtzLens:
        """The pose's measured lens, or the data sheet's straight line (the follower's)."""
        return self.follower.lens

    # --- what comes in ----------------------------------------------------------------------

    def take_pose(self, msg: m.CameraPose, now: float) -> str:
        """The calibration service's answer (``pose_source.py``): ``taken``, ``same`` (the
        pose it has) or ``future`` (refused: one such pose used to win for good)."""
        if msg.measured_s - now > self.max_future_s:
            return "future"
        if self.pose_msg is not None and msg.model_dump(exclude={"sent_s"}) == \
                self.pose_msg.model_dump(exclude={"sent_s"}):
            return "same"
        self.pointing.forget()
        self.infrared.again()
        self.pose_msg, self.pose = msg, Pose.of(msg)
        self.follower.lens = lens_of(msg)
        return "taken"

    def command(self, msg: m.RobotPosition, now: float, calibrating: bool) -> Command | None:
        """The move this robot sample asks for, or None."""
        self.robot = msg
        if (self.pose is None or self.limits is None or now < self.retry_at or calibrating
                or self.held_by or self.override.paused(now)):
            return None
        return self.follower.command(now, _xyz(msg), _velocity(msg), msg.measured_s, self.pose)

    def commanded(self, now: float, command: Command) -> None:
        """The camera took the command."""
        self.override.commanded(now, command.pan_deg, command.tilt_deg)

    def camera_limits(self, limits: PtzLimits, picture: tuple[int, int]) -> None:
        """What the camera says it is: how far it turns, how large its picture is (a lens
        not measured yet is the data sheet's straight line in that picture)."""
        self.limits = self.follower.limits = limits
        if self.pose_msg is None or not self.pose_msg.lens:
            width, height = picture
            self.follower.lens = PtzLens(straight_line(width), width_px=width,
                                         height_px=height)

    # --- the camera's health ------------------------------------------------------------------

    def may_try(self, now: float) -> bool:
        return now >= self.retry_at

    def failed(self, now: float) -> None:
        """The camera failed: wait, twice as long each time in a row; ask its limits again
        (it may have been replaced or reconfigured). Where it comes back is no one's hand
        (a reboot sends it home): judged from there on, and sent a fresh command."""
        self.retry_at, self.retry_s = now + self.retry_s, doubled(self.retry_s, RETRY_MAX_S)
        self.limits = None
        self.override.lost_sight()
        self.follower.forget()
        self.infrared.again()

    def infrared_due(self, now: float, recording: bool) -> bool:
        """Whether the preview about to be taken goes in infrared for the pointing check
        (``InfraredSchedule``); if so, it counts as taken."""
        if self.pose is None or not self.infrared.due(
                now, doubting=self.pointing.doubting(), recording=recording):
            return False
        self.infrared.taken(now)
        return True

    def answered(self) -> None:
        self.retry_s = RETRY_FIRST_S

    def own_move(self, now: float, pan_deg: float | None, tilt_deg: float | None) -> None:
        """Calibration mode sent the camera here (None: home, or kept): ours, not a hand."""
        self.override.own_move(now, pan_deg, tilt_deg)

    def calibration_left(self) -> None:
        """Calibration mode moved the camera: the next sample sends a fresh command."""
        self.follower.forget()

    def take_hand(self, msg: m.PtzHand, now: float, calibrating: bool) -> str | None:
        """An operator's hand (the page): None when it is taken — the camera held by them, or
        following again for ``follow``; a move (``HAND_MOVES``) is then the caller's to make,
        and ``moved_by_hand`` its to say — or why it is not: sent too long ago (it was meant
        for another moment), or a move while the camera is in calibration mode (it would spoil
        the passpoints)."""
        age = now - msg.measured_s
        if abs(age) > HAND_MAX_AGE_S:
            return f"sent {age:.1f} s ago (at most {HAND_MAX_AGE_S:g} s)"
        if msg.action in HAND_MOVES and calibrating:
            return (f"{msg.camera} is in calibration mode (a move would spoil its passpoints); "
                    "again once the calibration has ended")
        if msg.action == "follow":
            self.release()
        else:
            self.hold(msg.operator)
        return None

    def hold(self, by: str) -> None:
        """An operator holds the camera: it follows no more, and their moves are not someone
        else's hand (``moved_by_hand``)."""
        self.held_by = by or "an operator"
        self.override.forget()

    def moved_by_hand(self) -> None:
        """The holding operator moved it: no reference for the override detector."""
        self.override.forget()

    def release(self) -> None:
        """Following again: the next sample sends a fresh command."""
        self.held_by = ""
        self.override.forget()
        self.follower.forget()
    # --- what goes out --------------------------------------------------------------------

    @staticmethod
    def on_the_wire(pan_deg: float, tilt_deg: float, zoom: int) -> tuple[float, float, int]:
        """A position as ``PtzState`` carries it: a camera that reports beyond the message's
        ranges (a pan of 181°, zoom 0) is shown at their edge, not refused by the bus."""
        return (min(max(pan_deg, -180.0), 180.0), min(max(tilt_deg, -90.0), 90.0),
                min(max(zoom, 1), 19999))

    def status(self, now: float, pan_deg: float, tilt_deg: float, calibrating: bool,
               zoom: int | None = None) -> Status:
        """The status from where the camera is now (this also watches for someone else's
        hand on it, and tells the follower where the camera looks)."""
        if zoom is not None:
            self.follower.seen(pan_deg, tilt_deg, zoom)
        manual = not self.held_by and self._watch_hands(now, pan_deg, tilt_deg, calibrating)
        problem = self.pointing.problem() or ""
        pointing = self.pointing.error_deg
        status: m.PtzStatus = (
            "calibrating" if calibrating else "held" if self.held_by
            else "manual" if manual else "waiting_for_pose" if self.pose is None
            else "tracking" if self.robot else "idle")
        health: m.HealthStatus
        if self.pose is None:
            health, why = "degraded", self.pose_problem or "waiting for a camera pose from calib"
        else:
            why = "; ".join(w for w in (problem and f"{problem} — the pose asked of calib again",
                                        self.pose_problem) if w)
            health = "degraded" if why else "ok"
        error = 0.0
        if self.pose is not None and self.robot is not None:
            error = aim_error_deg(_xyz(self.robot), self.pose, pan_deg, tilt_deg)
        return Status(status, error, pointing if pointing != NOT_SEEN else None, problem,
                      health, why)

    def _watch_hands(self, now: float, pan: float, tilt: float, calibrating: bool) -> bool:
        if calibrating:  # calibration mode holds the camera (its moves: ``own_move``)
            self.override.watch_only(pan, tilt)
            self.manual = False
            return False
        if self.override.observe(now, pan, tilt) and not self.manual:
            log.warning("%s: moved by someone else (now pan %.1f°, tilt %.1f°): following "
                        "paused for %g s", self.name, pan, tilt, self.override.pause_s)
        paused = self.override.paused(now)
        if self.manual and not paused:
            log.info("%s: following again after a manual move", self.name)
            self.follower.forget()  # the next sample sends a fresh command
        self.manual = paused
        return paused


def _xyz(robot: m.RobotPosition) -> np.ndarray:
    return np.array([robot.x_mm, robot.y_mm, robot.z_mm])


def _velocity(robot: m.RobotPosition) -> np.ndarray:
    return np.array([robot.vx_mm_s, robot.vy_mm_s, robot.vz_mm_s])
