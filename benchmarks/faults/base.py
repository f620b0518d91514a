"""What every fault of the campaign shares: the lab's handles, the operator's side, the
services' memory, and the judgement after a fault (is every camera back on the robot, the
crane back with it). The faults are in the mixins that derive from it; ``Campaign`` joins
them."""

from __future__ import annotations

import random
import subprocess
import time
from pathlib import Path

import numpy as np
import zenoh

from benchmarks.faults.lab import ALIVE, private_mb, shared_mb, threads, wait_until
from benchmarks.faults.meters import Meters
from benchmarks.faults.rows import (
    GOAL_AIM_BACK_S,
    GOAL_AIM_DEG,
    GOAL_FLAT_MB,
    GOAL_MEMORY_MB,
    Row,
    duration_text,
    largest,
    least_growth,
)
from common import keys
from common import messages as m
from common.bus import Bus
from common.settings import BusSettings
from services.gantry.settings import GantrySettings
from services.ptz.aim import aim_error_deg
from tests.calib.test_demo_calibration import MOUNTS

GOAL_CRANE_BACK_S = 5.0
SETTLED_S = 1.0  # "back" once every sample of this long is within the goal


class CampaignBase:
    """The lab under test and the operator's side of it."""

    def __init__(self, up: subprocess.Popen, meters: Meters, bus: Bus, session: zenoh.Session,
                 short: bool, crane_port: int, web_url: str = "", endpoint: str = "",
                 folder: Path = Path(), lab: Path = Path()) -> None:
        self.up, self.meters, self.bus, self.session = up, meters, bus, session
        self.short, self.crane_port, self.web_url = short, crane_port, web_url
        self.endpoint, self.folder, self.lab = endpoint, folder, lab  # router; files; lab file
        self.gantry = GantrySettings()
        self.max_age_s = BusSettings().max_age_s
        self.rows: list[Row] = []
        self.rng = random.Random(1)
        self.commands = 0
        self.threads_before: dict[str, float] = {}
        self.shared_before: dict[str, float] = {}
        self.normal_mm = 100.0  # the baseline's largest crane–robot gap, once measured

    def log(self, text: str) -> None:
        print(f"[{time.strftime('%H:%M:%S')}] {text}", flush=True)

    # --- the operator ---

    def operator(self, command: str) -> m.GantryCommandReply | None:
        self.commands += 1
        ident = f"campaign-{self.commands}"
        self.bus.publish(keys.GANTRY_COMMAND, m.GantryCommand(
            measured_s=time.time(), command=command, operator="fault campaign",  # type: ignore[arg-type]
            reason="fault campaign", id=ident), sender="operator")
        def reply() -> m.GantryCommandReply | None:
            return next((r for r in self.meters.replies if r.id == ident), None)
        wait_until(lambda: reply() is not None, timeout=3)
        return reply()

    def follow(self, timeout: float = 60.0, since_s: float = 0.0) -> bool:
        """Reset a latched fault if there is one, arm, and wait until the crane tracks, as
        the gantry's states measured after ``since_s`` (wall clock) say."""
        def tracking() -> bool:
            state = self.meters.states[-1] if self.meters.states else None
            if state is not None and state.measured_s <= since_s:
                return False  # a state from before (a killed gantry's last one)
            if state is not None and state.mode != "armed":
                self.operator("reset")  # clears a latched fault, as an operator would
                self.operator("arm")  # refused without a fresh estimate: asked again
            return state is not None and state.mode == "armed" and state.status == "tracking"
        # two commands a second: what the gantry takes from one sender ([gantry] command_per_s)
        return wait_until(tracking, timeout, period=1.0)

    def snapshot_memory(self) -> dict[str, float]:
        return {s: private_mb(self.meters.pid(s) or -1) for s in ALIVE}

    def shared_memory(self) -> dict[str, float]:
        return {s: shared_mb(self.meters.pid(s) or -1) for s in ALIVE}

    def settled_memory(self, timeout: float = 40.0) -> dict[str, float]:
        """Every service's own memory once none has changed by more than 2 MB in 3 s (1.5 s
        with ``--short``): a service that has just started still grows as it warms up, which
        is not the fault's doing."""
        history = [self.snapshot_memory()]
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            time.sleep(0.5 if self.short else 1.0)
            history.append(self.snapshot_memory())
            recent = history[-4:]
            if len(recent) == 4 and all(abs(r[s] - recent[0][s]) <= 2.0
                                        for r in recent for s in ALIVE):
                break
        self.threads_before, self.shared_before = self.threads(), self.shared_memory()
        return history[-1]

    def threads(self) -> dict[str, float]:
        return {s: threads(self.meters.pid(s) or -1) for s in ALIVE}

    def pids(self) -> dict[str, int | None]:
        return {s: self.meters.pid(s) for s in ALIVE}

    def _shared_text(self) -> str:
        if not self.shared_before:
            return ""
        service, grown = largest(self.shared_before, self.shared_memory())
        return f"; shared memory mapped: {service} {grown:+.1f} MB" if grown > 1 else ""

    def _survived(self, fault: str, what: str, start: float, pids: dict,
                  rounds: list[tuple[dict, dict]], extra: dict | None = None, ok: bool = True,
                  again: bool = False) -> None:
        """One row from the memory (before, after) of each round of the fault; repeated
        (``again``), a service's growth is the least of its rounds' (``least_growth``)."""
        deaths = self.meters.deaths(start)
        worst, grown = least_growth(rounds)
        bound = GOAL_FLAT_MB if again else GOAL_MEMORY_MB
        misses = ((["crash"] if deaths or self.pids() != pids else []) +
                  (["memory"] if grown > bound else []) + ([] if ok else ["check"]))
        growth = f"largest growth {worst} {grown:+.1f} MB"
        if len(rounds) > 1:
            each = " / ".join(f"{after[worst] - before[worst]:+.1f}" for before, after in rounds)
            growth = f"least growth over {len(rounds)} rounds {worst} {grown:+.1f} MB ({each})"
        extra_text = "".join(f"; {k} {v}" for k, v in (extra or {}).items())
        goal = (f"0 crashes; no service's own memory grows by more than {bound:g} MB in each "
                f"of {len(rounds)} rounds (no leak)" if again else
                f"0 crashes; every service's own memory ≤ +{bound:g} MB")
        self.rows.append(Row(
            fault, goal, f"{what}: restarts {len(deaths)}, {growth}{extra_text}"
            f"{self._shared_text()}", not misses,
            {"memory_before_mb": rounds[0][0], "memory_after_mb": rounds[-1][1],
             "rounds_mb": rounds,
             "threads_before": self.threads_before, "threads_after": self.threads(),
             "shared_before_mb": self.shared_before, "shared_after_mb": self.shared_memory(),
             **(extra or {})}, misses))
        self.log(f"{fault}: {self.rows[-1].measured}")

    # --- after a fault: back to the robot? ----------------------------------------------

    def recovery(self, end: float, crane_bound_mm: float) -> tuple[float | None, float | None]:
        """Seconds after ``end`` (monotonic) until every camera's true aim error and the
        crane's gap to the robot stayed within their goals for ``SETTLED_S``; None: not
        within ``GOAL_AIM_BACK_S`` / ``GOAL_CRANE_BACK_S``."""
        def measured() -> tuple[float | None, float | None]:
            aim_back = [self._settled(end, self._aim(camera, end), GOAL_AIM_DEG,
                                      GOAL_AIM_BACK_S) for camera in MOUNTS]
            crane = [(t, gap) for t, _, _, gap in self.meters.crane_window(end)]
            known = [a for a in aim_back if a is not None]
            return ((max(known) if len(known) == len(aim_back) else None),
                    self._settled(end, crane, crane_bound_mm, GOAL_CRANE_BACK_S))

        wait_until(lambda: None not in measured(),
                   max(0.0, end + GOAL_AIM_BACK_S + SETTLED_S + 0.5 - time.monotonic()), 0.5)
        return measured()

    def _aim(self, camera: str, start: float) -> list[tuple[float, float]]:
        with self.meters.lock:
            seen = [(t, head, robot) for t, head, robot in self.meters.ptz
                    if t >= start and head.camera == camera]
        return [(t, aim_error_deg(np.array([r.x_mm, r.y_mm, r.z_mm]), MOUNTS[camera],
                                  head.pan_deg, head.tilt_deg)) for t, head, r in seen]

    @staticmethod
    def _settled(end: float, samples: list[tuple[float, float]], bound: float,
                 within_s: float) -> float | None:
        for i, (t, _) in enumerate(samples):
            if t - end > within_s:
                return None
            window = [v for u, v in samples[i:] if u <= t + SETTLED_S]
            if samples[-1][0] >= t + SETTLED_S and all(v <= bound for v in window):
                return t - end
        return None

    def crane_held(self, start: float, end: float, baseline: dict
                   ) -> tuple[float, float | None, float | None, str, list[str]]:
        """Spoofed frames from ``start`` to ``end``: the crane's largest gap to the robot
        meanwhile (goal: ≤ 2× the baseline's, or + 100 mm), and the recovery after them."""
        crane = self.meters.crane_window(start, end)
        worst = float(crane[:, 3].max()) if len(crane) else float("nan")
        bound = max(2 * baseline["max_mm"], baseline["max_mm"] + 100)
        aim, back = self.recovery(end, baseline["max_mm"])
        after, misses = self._back_text(aim, back)
        return worst, aim, back, after, ([] if worst <= bound else ["dragged"]) + misses

    def _back_text(self, aim: float | None, crane: float | None) -> tuple[str, list[str]]:
        misses = ([] if aim is not None else ["aim not back"]) + \
            ([] if crane is not None else ["crane not back"])
        return (f"; after: every camera's true aim ≤ {GOAL_AIM_DEG:g}° after "
                f"{duration_text(aim)}, crane with the robot after {duration_text(crane)}"), misses
