"""The campaign: the lab, the meters, every fault in turn, the table."""

from __future__ import annotations

import random
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import zenoh

from benchmarks.faults.bus_faults import BusFaults
from benchmarks.faults.file_faults import FileFaults
from benchmarks.faults.lab import (
    ALIVE,
    open_when_up,
    ports_of,
    private_mb,
    running_lab,
    shared_mb,
    threads,
    wait_until,
)
from benchmarks.faults.meters import Meters
from benchmarks.faults.process_faults import ProcessFaults
from benchmarks.faults.rows import GOAL_FLAT_MB, GOAL_MEMORY_MB, Row, largest, least_growth
from benchmarks.faults.trust_faults import TrustFaults
from benchmarks.faults.web_faults import WebFaults
from common import keys
from common import messages as m
from common.bus import Bus
from common.settings import BusSettings, ZenohSettings
from services.gantry.settings import GantrySettings


class Campaign(BusFaults, ProcessFaults, WebFaults, TrustFaults, FileFaults):
    """The operator's side and the bookkeeping; the faults are in the bases."""

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
        found: list[m.GantryCommandReply] = []
        wait_until(lambda: found.extend(r for r in self.meters.replies if r.id == ident)
                   or found, timeout=3)
        return found[0] if found else None

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

    # --- steps ---

    def baseline(self) -> dict:
        # "tracking" comes while the crane still closes in on the robot
        time.sleep(3 if self.short else 5)
        start = time.monotonic()
        time.sleep(3 if self.short else 10)
        crane = self.meters.crane_window(start)
        self.normal_mm = float(crane[:, 3].max())  # the crane "with the robot" after a fault
        return {"rms_mm": float(np.sqrt(np.mean(crane[:, 3] ** 2))), "max_mm": self.normal_mm}

    def totals(self, started: float) -> None:
        crane = self.meters.crane_window(started)
        g = self.gantry
        setpoints = self.meters.setpoints_since(started)
        outside = sum(not (g.x_min_mm <= sp.x_mm <= g.x_max_mm and
                           g.y_min_mm <= sp.y_mm <= g.y_max_mm) for _, sp, _ in setpoints)
        inside = bool(((crane[:, 1] >= g.x_min_mm) & (crane[:, 1] <= g.x_max_mm) &
                       (crane[:, 2] >= g.y_min_mm) & (crane[:, 2] <= g.y_max_mm)).all())
        self.rows.append(Row(
            "whole campaign", "0 setpoints outside the workspace; crane inside it",
            f"{len(setpoints)} setpoints, {outside} outside; crane x {crane[:, 1].min():.0f}…"
            f"{crane[:, 1].max():.0f}, y {crane[:, 2].min():.0f}…{crane[:, 2].max():.0f} mm",
            outside == 0 and inside, {"setpoints": len(setpoints), "outside": outside}))

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


STEPS = ["quiet", "fuzz", "churn", "bombs", "frames", "pose", "drift", "calibration-flood",
         "command-flood", "origin", "crater-file", "streams", "sign-ins", "viewer-sign-ins",
         "forwarded-for", "host", "bodies", "report-link", "calibration-move", "disk-fill",
         "crater-import", "stalls", "tracker", "modbus", "camera-reboot", "kill"]


def run(short: bool, per_key: int, churn: int, folder: Path,
        only: list[str] | None = None) -> list[Row]:
    with running_lab(folder) as (up, lab, endpoint):
        ports = ports_of(lab)
        settings = BusSettings(zenoh=ZenohSettings(mode="client", connect=[endpoint]))
        session = open_when_up(settings.zenoh)
        bus = Bus(session, settings)
        meters = Meters(session, bus, ports["crane"])
        try:
            campaign = Campaign(up, meters, bus, session, short, ports["crane"],
                                f"http://127.0.0.1:{ports['web']}", endpoint, folder, lab)
            campaign.log("lab starting; waiting until every service is alive")
            if not wait_until(lambda: all(campaign.meters.pid(s) for s in ALIVE), 90, 0.5):
                raise SystemExit(f"the lab did not come up: see {folder / 'logs'}")
            if not campaign.follow(90):
                raise SystemExit(f"the crane never tracked: see {folder / 'logs'}")
            wait_until(lambda: any(p.camera == "ptz1" for _, p in meters.poses), 10)
            started = time.monotonic()
            baseline = campaign.baseline()
            campaign.log(f"baseline: crane–robot rms {baseline['rms_mm']:.0f} mm, "
                         f"max {baseline['max_mm']:.0f} mm")
            steps: dict[str, Callable[[], None]] = {
                "quiet": campaign.quiet,
                "fuzz": lambda: [campaign.fuzz(per_key, again) for again in (False, True)],
                "churn": lambda: [campaign.churn(churn, again) for again in (False, True)],
                "bombs": campaign.decode_bombs,
                "frames": lambda: campaign.spoofed_frames(baseline),
                "pose": campaign.spoofed_pose,
                "drift": lambda: campaign.drifting_frames(baseline),
                "calibration-flood": lambda: campaign.calibration_flood(baseline),
                "command-flood": lambda: campaign.command_flood(baseline),
                "origin": campaign.foreign_origin,
                "crater-file": campaign.crater_rewrite,
                "streams": campaign.event_streams,
                "sign-ins": campaign.sign_in_flood,
                "viewer-sign-ins": campaign.viewer_sign_ins,
                "forwarded-for": campaign.forwarded_for,
                "host": campaign.foreign_host,
                "bodies": campaign.huge_bodies,
                "report-link": campaign.report_link,
                "calibration-move": campaign.calibration_move,
                "disk-fill": campaign.disk_filled,
                "crater-import": campaign.crater_imports,
                "stalls": lambda: [campaign.stall("gantry", seconds) for seconds in
                                   ((0.3, 1.0) if short else (0.3, 1.0, 3.0))],
                "tracker": lambda: campaign.stall("tracker", 2.0),
                "modbus": lambda: campaign.foreign_modbus(baseline),
                "camera-reboot": campaign.camera_reboot,
                "kill": campaign.kill_each}
            for name in only or list(steps):
                campaign.follow()  # each fault starts from a crane that follows the robot
                steps[name]()
            campaign.totals(started)
            return campaign.rows
        finally:
            meters.close()
            bus.close()
            session.close()


def table(rows: list[Row]) -> str:
    lines = ["| fault | goal | measured | held |", "|---|---|---|---|"]
    lines += [f"| {r.fault} | {r.goal} | {r.measured} | {'yes' if r.held else '**no**'} |"
              for r in rows]
    return "\n".join(lines)
