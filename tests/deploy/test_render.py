"""`stb deploy render`: the router's access control and the compose services from the lab
file. The committed files are its output for the example lab; a camera added to a lab file
is a working identity behind a real router and a valid compose service."""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from services.deploy.cli import main as deploy
from tests.conftest import ROOT
from tests.deploy.lab_secrets import only_allowed_arrive, secured_router
from tests.deploy.test_compose import COMPOSE

EXAMPLE_LAB = ROOT / "config" / "lab.example.toml"


def test_the_committed_files_are_what_the_example_lab_renders() -> None:
    assert deploy(["render", "--lab", str(EXAMPLE_LAB), "--check", "--out", str(ROOT)]) == 0


def test_a_hand_edit_is_drift(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert deploy(["render", "--lab", str(EXAMPLE_LAB), "--out", str(tmp_path)]) == 0
    compose = tmp_path / "docker-compose.yml"
    compose.write_text(compose.read_text().replace("ptz-2:", "ptz-two:"))
    capsys.readouterr()
    assert deploy(["render", "--lab", str(EXAMPLE_LAB), "--check", "--out", str(tmp_path)]) == 1
    assert f"{compose} differs from what the lab file renders" in capsys.readouterr().err


def test_a_bad_camera_name_stops_naming_the_field(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    lab = tmp_path / "lab.toml"
    lab.write_text('[ptz.cameras.North]\nurl = "http://10.0.0.9"\n')
    assert deploy(["render", "--lab", str(lab), "--out", str(tmp_path)]) == 2
    assert "ptz.cameras.North" in capsys.readouterr().err
    assert not (tmp_path / "docker-compose.yml").exists()


def _lab_with_a_third_camera(folder: Path) -> Path:
    lab = folder / "lab.toml"
    lab.write_text(EXAMPLE_LAB.read_text() + '\n[ptz.cameras.ptz3]\nurl = "http://10.0.0.9"\n'
                   'user = "root"\npassword = "pass"\n')
    return lab


@pytest.fixture
def rendered(tmp_path: Path) -> Iterator[dict]:
    """A lab folder for a lab file with a third camera: rendered, with the secrets that
    make-secrets makes next to the rendered router config, and its router running."""
    lab = _lab_with_a_third_camera(tmp_path)
    assert deploy(["render", "--lab", str(lab), "--out", str(tmp_path)]) == 0
    shutil.copy(ROOT / "deploy" / "zenoh" / "make-secrets", tmp_path / "deploy" / "zenoh")
    made = subprocess.run([str(tmp_path / "deploy" / "zenoh" / "make-secrets")],
                          capture_output=True, text=True, timeout=60, check=True)
    assert "ptz3" in made.stdout.splitlines()[-1]  # users.txt lists: ... ptz3 ...
    with secured_router(tmp_path / "deploy/zenoh/router.json5", tmp_path,
                        tmp_path / "deploy/zenoh/secrets") as (_, session):
        yield {"folder": tmp_path, "session": session}


def test_a_camera_added_to_the_lab_file_writes_only_its_own_keys(rendered: dict) -> None:
    only_allowed_arrive(rendered["session"], [
        ("ptz3", "stb/ptz/ptz3/state", b"ptz3 about itself"),
        ("ptz3", "stb/health/ptz/ptz3", b"ptz3 health"),
        ("ptz3", "stb/ptz/ptz1/state", b"ptz3 about ptz1"),
        ("ptz3", "stb/gantry/setpoint", b"ptz3 moves the crane"),
        ("ptz1", "stb/ptz/ptz1/state", b"ptz1 about itself"),
        ("ptz1", "stb/ptz/ptz3/state", b"ptz1 about ptz3"),
    ], allowed={b"ptz3 about itself", b"ptz3 health", b"ptz1 about itself"})


def test_a_camera_added_to_the_lab_file_is_a_compose_service(rendered: dict) -> None:
    folder = rendered["folder"]
    shutil.copytree(ROOT / "config", folder / "config")
    done = subprocess.run([str(COMPOSE), "-f", str(folder / "docker-compose.yml"), "--profile",
                           "sim", "config", "--services"], capture_output=True, text=True,
                          timeout=60, cwd=folder, check=False)
    assert done.returncode == 0, done.stderr
    assert {"ptz-1", "ptz-2", "ptz-3"} <= set(done.stdout.split())
    config = subprocess.run([str(COMPOSE), "-f", str(folder / "docker-compose.yml"),
                             "config", "ptz-3"], capture_output=True, text=True, timeout=60,
                            cwd=folder, check=True).stdout
    assert "--instance" in config and "ptz3" in config and "ptz3.password" in config
