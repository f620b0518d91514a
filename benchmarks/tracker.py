"""The tracker at QTM's full rate: frames dropped, frame → publish latency, CPU per process.

    .venv/bin/python -m benchmarks.tracker [--seconds 20] [--rate 1000] [--markers 20]
    .venv/bin/python -m benchmarks.tracker --ladder 2 --seconds 10   # floor levels, tracker

Runs the real path as separate processes on loopback: the sim's QTM RT server (its
"devices" part, with the crane, as in ``benchmarks.ptz``) streaming at ``--rate`` Hz with
about ``--markers`` markers a frame (static markers added to the sim's robot, wand, bodies
and ghosts), ``stb router`` and ``stb tracker``. This process is the monitor: a plain Zenoh
subscriber on ``stb/tracker/robot`` and ``stb/tracker/markers`` that stamps each sample when
it arrives and decodes it only after the phase.

Measured over one phase of ``--seconds``:

* frames the sim wrote, marker frames and robot samples that reached the monitor, and the
  frames missing from the marker frames' numbers between the first and the last received;
* frame → publish: from the sim writing a frame to the tracker's socket (its time just before
  the write) to the tracker publishing the marker frame with that number (its ``sent_s``,
  which the bus stamps just before the put; one clock, one host) — and on to the monitor
  (through the router); p50 / p99;
* CPU of the tracker, the sim's QTM process, the router and this monitor: their user + system
  time over the phase (/proc), as a share of one core.

``--floor LEVEL`` puts ``benchmarks.tracker_floor`` in the tracker's place (what receiving and
two puts a frame cost, then reading the markers, then the picker; its docstring has the
levels); ``--ladder N`` runs each level and the tracker in turn, N times, and prints their CPU
in one table.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from benchmarks.ptz import _open, _sim_process, _stb
from benchmarks.tracker_floor import LEVELS
from common import codec, keys
from common import messages as m
from services.args import Parser
from services.sim.lab import Lab
from services.sim.settings import CraneSettings, MocapSettings, SimSettings
from tests.ports import free_port

TICKS = os.sysconf("SC_CLK_TCK")


def _cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process (and its threads) so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


def _markers_per_frame(settings: SimSettings) -> int:
    lab = Lab.build(settings)
    frame = lab.mocap_frame(1)
    return int(np.isfinite(frame.labelled).all(axis=1).sum()) + len(frame.unlabelled)


def _settings(workdir: Path, rate_hz: float, markers: int) -> SimSettings:
    """The sim streaming at ``rate_hz`` with static markers added to reach ``markers``."""
    base = SimSettings(crater_file=workdir / "crater.npz", loop=True,
                       mocap=MocapSettings(port=free_port(), rate_hz=rate_hz),
                       crane=CraneSettings(port=free_port()), cameras=[])
    others = _markers_per_frame(base) - base.mocap.static_markers
    static = min(20, max(0, markers - others))
    return base.model_copy(update={"mocap": base.mocap.model_copy(
        update={"static_markers": static})})


class Monitor:
    """Arrival time and payload of every sample on the tracker's two keys; decoded later."""

    def __init__(self, session, prefix: str = "stb") -> None:  # noqa: ANN001 - zenoh.Session
        self.robot: list[tuple[float, bytes]] = []
        self.markers: list[tuple[float, bytes]] = []
        self.recording = threading.Event()
        self.flowing = threading.Event()  # a marker frame has arrived
        self._subs = [
            session.declare_subscriber(keys.TRACKER_ROBOT.key(prefix), self._into(self.robot)),
            session.declare_subscriber(keys.TRACKER_MARKERS.key(prefix),
                                       self._into(self.markers))]

    def _into(self, store: list):  # noqa: ANN202
        def on_sample(sample) -> None:  # noqa: ANN001
            self.flowing.set()
            if self.recording.is_set():
                store.append((time.time(), bytes(sample.payload.to_bytes())))
        return on_sample

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()


def run(seconds: float, rate_hz: float, markers: int, workdir: Path,
        profile: Path | None = None, floor: str | None = None) -> dict:
    """``floor``: ``benchmarks.tracker_floor`` at that level (``receive``: two puts a frame,
    nothing else) in the tracker's place."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    settings = _settings(workdir, rate_hz, markers)
    Lab.build(settings)  # writes the crater file once, before the sim process reads it
    t0 = time.monotonic() + 3.0
    parent, child = mp.Pipe()
    sim = mp.get_context("spawn").Process(
        target=_sim_process, args=(settings.model_dump_json(), "devices", t0, child))
    sim.start()
    parent.recv()
    lab_file = workdir / "lab.toml"
    lab_file.write_text(f'[bus.zenoh]\nconnect = ["{endpoint}"]\n'
                        f"[tracker]\nqtm_port = {settings.mocap.port}\n")
    procs = [_stb("router", "--listen", endpoint, lab=lab_file)]
    session = _open(endpoint)
    monitor = Monitor(session)
    try:
        if floor:
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "benchmarks.tracker_floor", "--qtm-port",
                 str(settings.mocap.port), "--connect", endpoint, "--level", floor]))
        elif profile is None:
            procs.append(_stb("tracker", lab=lab_file))
        else:  # the same command under cProfile
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "cProfile", "-o", str(profile), "-m", "services.cli",
                 "tracker", "--lab", str(lab_file)], stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL))
        if not monitor.flowing.wait(60):
            raise RuntimeError("no marker frame from the tracker within 60 s")
        time.sleep(2.0)  # streaming, past the start-up
        assert sim.pid is not None, "the sim's process has started"
        pids = {_in_place(floor): procs[1].pid, "sim (QTM)": sim.pid, "router": procs[0].pid,
                "monitor": os.getpid()}
        parent.send("start")  # the sim logs what it writes from now
        cpu = _phase(monitor, pids, seconds)
        parent.send("stop")
        sent = dict(parent.recv()["mocap_sent"])
        parent.send("end")
        if floor:
            return {"rate_hz": rate_hz, "seconds": seconds, "frames_sent": len(sent),
                    "marker_samples": len(monitor.markers), "robot_samples": len(monitor.robot),
                    "cpu_share": _cpu_shares(cpu), "floor": floor}
        return _summary(seconds, rate_hz, sent, monitor, cpu)
    finally:
        monitor.close()
        for proc in procs[::-1]:
            proc.terminate()
        for proc in procs[::-1]:
            proc.wait(10)
        session.close()
        sim.join(10)


def run_loaded(seconds: float, rate_hz: float, markers: int, workdir: Path) -> dict:
    """The same measurement on the whole simulated lab under ``stb up`` (sim with its cameras,
    tracker, calib, both PTZ services, gantry, web) with the sim's QTM at ``rate_hz``."""
    from benchmarks.faults.lab import open_when_up, running_lab
    from common.settings import ZenohSettings

    static = _settings(workdir, rate_hz, markers).mocap.static_markers
    with running_lab(workdir, mocap={"rate_hz": rate_hz, "static_markers": static}) as (
            up, _lab, endpoint):
        session = open_when_up(ZenohSettings(connect=[endpoint], connect_timeout_ms=0))
        monitor = Monitor(session)
        try:
            if not monitor.flowing.wait(120):
                raise RuntimeError("no marker frame from the tracker within 120 s")
            time.sleep(10.0)  # the other services started and following
            pids = _lab_processes(up.pid)
            pids["monitor"] = os.getpid()
            cpu = _phase(monitor, pids, seconds)
        finally:
            monitor.close()
            session.close()
    result = _summary(seconds, rate_hz, {}, monitor, cpu)
    result["lab"] = "whole lab (stb up)"
    return result


def _phase(monitor: Monitor, pids: dict[str, int], seconds: float) -> dict[str, float]:
    """The monitor records for ``seconds``; each process's CPU over it, a share of one core."""
    before = {name: _cpu_s(pid) for name, pid in pids.items()}
    monitor.recording.set()
    started = time.monotonic()
    time.sleep(seconds)
    monitor.recording.clear()
    elapsed = time.monotonic() - started
    return {name: (_cpu_s(pid) - before[name]) / elapsed for name, pid in pids.items()}


def _lab_processes(up_pid: int) -> dict[str, int]:
    """Every service process under ``stb up`` by name (``ptz:ptz1``), and the sim's QTM
    process (a child of the sim's)."""
    from benchmarks.faults.lab import children, cmdline

    pids = {}
    for pid in children(up_pid):
        words = cmdline(pid).split()
        module = next((w for w in words if w.startswith("services.")), "")
        name = module.removeprefix("services.")
        instance = words[words.index("--instance") + 1] if "--instance" in words else "main"
        pids[name if instance == "main" else f"{name}:{instance}"] = pid
        if name == "sim":
            for child in children(pid):
                pids["sim's QTM"] = child
    return pids


def _summary(seconds: float, rate_hz: float, sent: dict[int, float], monitor: Monitor,
             cpu: dict[str, float]) -> dict:
    frames = [(arrived, codec.decode(m.MarkerFrame, payload))
              for arrived, payload in monitor.markers]
    numbers = sorted({f.frame for _, f in frames})
    sent = sent or {}
    expected = set(range(numbers[0], numbers[-1] + 1)) if numbers else set()
    latency_ms = np.array([(arrived - sent[f.frame]) * 1e3 for arrived, f in frames
                           if f.frame in sent])
    # the bus stamps sent_s just before the put: the tracker's own frame → publish
    publish_ms = np.array([(f.sent_s - sent[f.frame]) * 1e3 for _, f in frames
                           if f.frame in sent])
    # the same without the sim's log: from the frame's capture time on the tracker's clock
    # (QTM's stamp plus the smallest transport delay seen) to the put
    capture_ms = np.array([(f.sent_s - f.measured_s) * 1e3 for _, f in frames])
    return {
        "rate_hz": rate_hz, "seconds": seconds,
        "markers_per_frame": float(np.mean([len(f.markers) for _, f in frames]))
        if frames else 0.0,
        "frames_sent": len(sent) or None, "marker_frames": len(frames),
        "robot_samples": len(monitor.robot),
        "missing_frames": len(expected - set(numbers)),
        "capture_to_publish_ms_p50": _percentile(capture_ms, 50),
        "capture_to_publish_ms_p99": _percentile(capture_ms, 99),
        "publish_ms_p50": _percentile(publish_ms, 50),
        "publish_ms_p99": _percentile(publish_ms, 99),
        "monitor_ms_p50": _percentile(latency_ms, 50),
        "monitor_ms_p99": _percentile(latency_ms, 99),
        "cpu_share": _cpu_shares(cpu),
    }


def _cpu_shares(cpu: dict[str, float]) -> dict[str, float]:
    return {name: round(share, 3) for name, share in cpu.items()}


def _cpu_line(result: dict) -> str:
    return "CPU (share of one core): " + ", ".join(
        f"{name} {share:.0%}" for name, share in result["cpu_share"].items())


def _percentile(values: np.ndarray, q: float) -> float | None:
    return float(np.percentile(values, q)) if values.size else None


def _in_place(floor: str | None) -> str:
    """The name of the process in the tracker's place, as the CPU figures call it."""
    return f"tracker floor ({floor})" if floor else "tracker"


def _ladder(rounds: int, seconds: float, rate_hz: float, markers: int, as_json: bool) -> None:
    """Each floor level and the tracker in turn, ``rounds`` times (alternating, so that the
    machine's drift spreads over all of them); their CPU and the sim's QTM's per run."""
    steps = [*LEVELS, "tracker"]
    cpu: dict[str, list[tuple[float, float]]] = {step: [] for step in steps}
    for done in range(rounds * len(steps)):
        step = steps[done % len(steps)]
        with tempfile.TemporaryDirectory() as tmp:
            r = run(seconds, rate_hz, markers, Path(tmp),
                    floor=None if step == "tracker" else step)
        share = r["cpu_share"][_in_place(None if step == "tracker" else step)]
        cpu[step].append((share, r["cpu_share"]["sim (QTM)"]))
        print(f"[{done + 1}/{rounds * len(steps)}] {step}: {share:.0%} of a core",
              file=sys.stderr, flush=True)
    if as_json:
        print(json.dumps(cpu, indent=2))
        return
    print(f"{rate_hz:.0f} Hz, about {markers} markers a frame, {seconds:.0f} s a run, "
          f"{rounds} runs each, alternating (share of one core):")
    print("| in the tracker's place | its CPU, each run | the sim's QTM |")
    print("|---|---|---|")
    for step in steps:
        name = "the tracker (`stb tracker`)" if step == "tracker" else f"floor: {step}"
        print(f"| {name} | " + ", ".join(f"{c:.0%}" for c, _ in cpu[step]) + " | "
              + ", ".join(f"{q:.0%}" for _, q in cpu[step]) + " |")


def main() -> None:
    parser = Parser(description=__doc__,
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--rate", type=float, default=1000.0, help="QTM frame rate, Hz")
    parser.add_argument("--markers", type=int, default=20, help="markers a frame (about)")
    parser.add_argument("--lab", action="store_true",
                        help="on the whole simulated lab under stb up (every service running)")
    parser.add_argument("--profile", type=Path, metavar="FILE",
                        help="run the tracker under cProfile, its statistics into FILE")
    parser.add_argument("--floor", nargs="?", const="receive", choices=LEVELS,
                        help="benchmarks.tracker_floor in the tracker's place; receive (the "
                        "default): QTM's stream received and two Zenoh puts a frame, nothing "
                        "else; read: and the markers read and packed; pick: and the picker")
    parser.add_argument("--ladder", type=int, metavar="ROUNDS",
                        help="each floor level and the tracker in turn, ROUNDS times: their "
                        "CPU in one table")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.ladder:
        _ladder(args.ladder, args.seconds, args.rate, args.markers, args.json)
        return
    with tempfile.TemporaryDirectory() as tmp:
        result = (run_loaded(args.seconds, args.rate, args.markers, Path(tmp)) if args.lab
                  else run(args.seconds, args.rate, args.markers, Path(tmp), args.profile,
                           args.floor))
    if args.json:
        print(json.dumps(result, indent=2))
        return
    r = result
    if r.get("floor"):
        print(f"sim, router, the tracker's floor ({r['floor']}): {r['rate_hz']:.0f} Hz, "
              f"{r['seconds']:.0f} s: "
              f"the sim wrote {r['frames_sent']} frames; the monitor got "
              f"{r['marker_samples']} marker and {r['robot_samples']} robot samples")
        print(_cpu_line(r))
        return
    sent = "" if r["frames_sent"] is None else f"the sim wrote {r['frames_sent']} frames; "
    print(f"{r.get('lab', 'sim, router, tracker')}: {r['rate_hz']:.0f} Hz, "
          f"{r['markers_per_frame']:.1f} markers a frame, {r['seconds']:.0f} s: {sent}the monitor "
          f"got {r['marker_frames']} marker frames ({r['missing_frames']} missing) and "
          f"{r['robot_samples']} robot samples")
    if r["publish_ms_p50"] is not None:
        print(f"frame written → published by the tracker: p50 {r['publish_ms_p50']:.2f} ms, "
              f"p99 {r['publish_ms_p99']:.2f} ms; → at the monitor: "
              f"p50 {r['monitor_ms_p50']:.2f} ms, p99 {r['monitor_ms_p99']:.2f} ms")
    print(f"frame captured (tracker's clock) → published: p50 "
          f"{r['capture_to_publish_ms_p50']:.2f} ms, p99 {r['capture_to_publish_ms_p99']:.2f} ms")
    print(_cpu_line(r))


if __name__ == "__main__":
    main()
