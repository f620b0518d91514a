"""A Docker engine of the compose test's own: installed when missing (Debian's docker.io),
started by hand with its own data root, exec root, socket and pid file, and stopped by pid.

The project's image is built on the official Python base where a registry answers, else on
an offline Debian base (deploy/docker/make-base); the router runs upstream's eclipse/zenoh
where it can be pulled, else from the project's image (deploy/docker/compose.offline.yml).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

import compose

ROOT = Path(__file__).resolve().parents[1]
COMPOSE = Path(compose.__file__).parent / "docker-compose"  # the real v2 binary
OFFICIAL_BASE = "python:3.11-slim"
OFFLINE_BASE = "stb-base:bookworm"
IMAGE = "stb-supervisor:latest"
HOST_CA_BUNDLE = Path("/etc/ssl/certs/ca-certificates.crt")  # Debian's ca-certificates
BUILD_CA = ROOT / "deploy" / "docker" / "build-ca" / "ca-certificates.crt"
CAP_SYS_RESOURCE = 24
OUT = ROOT / "run" / "compose-test"
ENGINE_HOME = Path(os.environ.get("STB_ENGINE_HOME", "/var/tmp/stb-compose-engine"))


class EngineError(RuntimeError):
    """The engine cannot run here (the compose test skips) or a docker command failed."""


def why_no_engine() -> str | None:
    """None where an engine can be installed and started, else why not (one line)."""
    if os.geteuid() != 0:
        return "the Docker engine needs root (dockerd started by hand)"
    if shutil.which("dockerd") is None and shutil.which("apt-get") is None:
        return "no dockerd and no apt-get to install Debian's docker.io"
    return None


def install_when_missing(log: Path) -> None:
    """Debian's docker.io (dockerd, containerd, runc, the docker client) and debootstrap."""
    missing = [tool for tool in ("dockerd", "docker", "debootstrap") if shutil.which(tool) is None]
    if not missing:
        return
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    with log.open("ab") as out:
        for args in (["apt-get", "update", "-qq"],
                     ["apt-get", "install", "-y", "-qq", "--no-install-recommends", "docker.io",
                      "debootstrap"]):
            done = subprocess.run(args, stdout=out, stderr=subprocess.STDOUT, env=env,
                                  timeout=900, check=False)
            if done.returncode != 0:
                raise EngineError(f"cannot install docker.io ({' '.join(args)}: exit "
                                  f"{done.returncode}; see {log})")


def may_raise_limits() -> bool:
    """Whether this process (and so dockerd) holds CAP_SYS_RESOURCE: without it, the engine
    cannot give a container an rtprio limit above the host's (compose ulimits)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("CapEff:"):
            return bool(int(line.split()[1], 16) >> CAP_SYS_RESOURCE & 1)
    return False


@dataclass
class Engine:
    """dockerd with everything of its own under ``home``."""

    home: Path
    pid: int | None = None
    env: dict[str, str] = field(default_factory=dict)

    @property
    def socket(self) -> Path:
        return self.home / "docker.sock"

    @property
    def pid_file(self) -> Path:
        return self.home / "dockerd.pid"

    def start(self, timeout_s: float = 60.0) -> None:
        self.home.mkdir(parents=True, exist_ok=True)
        self._stop_leftover()
        self.env = {**os.environ, "DOCKER_HOST": f"unix://{self.socket}"}
        log = (self.home / "dockerd.log").open("ab")
        proc = subprocess.Popen(
            ["dockerd", "--data-root", str(self.home / "data"), "--exec-root",
             str(self.home / "exec"), "--pidfile", str(self.pid_file), "-H",
             f"unix://{self.socket}", "--storage-driver=overlay2", "--iptables=false",
             "--ip6tables=false", "--bridge=none"],
            stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        self.pid = proc.pid
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if proc.poll() is not None:
                raise EngineError(f"dockerd exited ({proc.returncode}): {self._last_log_line()}")
            if self.docker("version", check=False, timeout=10).returncode == 0:
                return
            time.sleep(0.5)
        self.stop()
        raise EngineError(f"dockerd did not answer within {timeout_s:.0f} s: "
                          f"{self._last_log_line()}")

    def stop(self) -> None:
        """Stop dockerd by its pid (it stops its containerd); SIGKILL after 30 s."""
        if self.pid is None:
            return
        _terminate(self.pid, 30.0)
        self.pid = None
        self._unmount_leftovers()

    def _unmount_leftovers(self) -> None:
        """dockerd leaves its network namespace file mounted under the exec root."""
        for line in Path("/proc/mounts").read_text().splitlines():
            point = line.split()[1]
            if point.startswith(f"{self.home}/"):
                subprocess.run(["umount", "-l", point], check=False, timeout=30)

    def _stop_leftover(self) -> None:
        """A dockerd of an earlier, interrupted run of this test (its pid file) is stopped."""
        try:
            pid = int(self.pid_file.read_text())
        except (OSError, ValueError):
            return
        if Path(f"/proc/{pid}/cmdline").exists() and b"dockerd" in Path(
                f"/proc/{pid}/cmdline").read_bytes():
            _terminate(pid, 30.0)

    def _last_log_line(self) -> str:
        lines = (self.home / "dockerd.log").read_text(errors="replace").strip().splitlines()
        return lines[-1] if lines else "(no output)"

    # --- commands ---------------------------------------------------------------------------

    def docker(self, *args: str, check: bool = True, timeout: float = 120.0,
               **env: str) -> subprocess.CompletedProcess:
        return self._run(["docker", *args], check=check, timeout=timeout, env=env)

    def compose(self, folder: Path, files: list[str], *args: str, check: bool = True,
                timeout: float = 300.0, project: str = "stb-compose-test",
                **env: str) -> subprocess.CompletedProcess:
        """``docker compose -p PROJECT -f FILE... ARGS`` in the lab's ``folder``."""
        cmd = [str(COMPOSE), "--project-directory", str(folder), "-p", project]
        for name in files:
            cmd += ["-f", str(folder / name)]
        return self._run([*cmd, *args], check=check, timeout=timeout, env=env, cwd=folder)

    def _run(self, cmd: list[str], *, check: bool, timeout: float, env: dict[str, str],
             cwd: Path | None = None) -> subprocess.CompletedProcess:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=cwd,
                              env={**self.env, **env}, check=False)
        if check and done.returncode != 0:
            raise EngineError(f"{' '.join(cmd[:4])} ...: exit {done.returncode}\n"
                              f"{done.stdout[-2000:]}{done.stderr[-3000:]}")
        return done

    def has_image(self, name: str) -> bool:
        return self.docker("image", "inspect", name, check=False).returncode == 0

    def pulled(self, name: str) -> bool:
        """True when ``name`` is here or could be pulled (a registry answered)."""
        return self.has_image(name) or self.docker("pull", name, check=False,
                                                   timeout=600).returncode == 0

    # --- the project's images ---------------------------------------------------------------

    def base_image(self) -> str:
        """The official Python base if a registry gives it, else the offline Debian one."""
        if self.pulled(OFFICIAL_BASE):
            return OFFICIAL_BASE
        if not self.has_image(OFFLINE_BASE):
            make_base = ROOT / "deploy" / "docker" / "make-base"
            done = subprocess.run([str(make_base), OFFLINE_BASE], capture_output=True,
                                  text=True, timeout=1200, env=self.env, check=False)
            if done.returncode != 0:
                raise EngineError(f"make-base failed: {done.stderr[-2000:]}")
        return OFFLINE_BASE

    def build(self, base: str) -> None:
        """The project's image from ROOT (the classic builder, host networking for pip), with
        the host's CA bundle in the build context only while it builds."""
        copied = HOST_CA_BUNDLE.is_file() and not BUILD_CA.exists()
        if copied:
            shutil.copyfile(HOST_CA_BUNDLE, BUILD_CA)
        try:
            self.docker("build", "--network", "host", "--build-arg", f"BASE={base}", "-t",
                        IMAGE, str(ROOT), timeout=1800, DOCKER_BUILDKIT="0")
        finally:
            if copied:
                BUILD_CA.unlink(missing_ok=True)

    def container_pid(self, container: str) -> int:
        return int(self.docker("inspect", "-f", "{{.State.Pid}}", container).stdout)

    def container_starts(self, container: str) -> tuple[str, int]:
        """(StartedAt, RestartCount): both unchanged when a container was not restarted."""
        out = self.docker("inspect", "-f", "{{.State.StartedAt}} {{.RestartCount}}",
                          container).stdout.split()
        return out[0], int(out[1])

    def image_size_mb(self, name: str) -> float:
        return int(self.docker("image", "inspect", "-f", "{{.Size}}", name).stdout) / 1e6


def _terminate(pid: int, timeout_s: float) -> None:
    try:
        os.kill(pid, signal.SIGTERM)
    except ProcessLookupError:
        return
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            if os.waitpid(pid, os.WNOHANG)[0] == pid:
                return
        except ChildProcessError:  # not our child: poll for it
            if not Path(f"/proc/{pid}").exists():
                return
        time.sleep(0.2)
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGKILL)
