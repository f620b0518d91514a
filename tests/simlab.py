"""A small simulated lab for tests: settings on free loopback ports, the crater made once."""

from __future__ import annotations

from pathlib import Path

import pytest

from services.sim.lab import Lab, load_or_make_crater
from services.sim.settings import (
    CraneSettings,
    MocapSettings,
    ObservationCameraSettings,
    PtzCameraSettings,
    SimSettings,
)
from services.sim.world import CraterMap
from tests.ports import free_port


def sim_settings(crater_file: Path, **changes: object) -> SimSettings:
    base = SimSettings()
    cameras = [PtzCameraSettings(**{**c.model_dump(), "port": free_port()}) for c in base.cameras]
    values = {"crater_file": crater_file, "cameras": cameras,
              "mocap": MocapSettings(port=free_port()), "crane": CraneSettings(port=free_port()),
              "observation_camera": ObservationCameraSettings(port=free_port()), **changes}
    return SimSettings(**values)


@pytest.fixture(scope="session")
def crater_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("sim") / "crater.npz"
    load_or_make_crater(SimSettings(crater_file=path))
    return path


@pytest.fixture(scope="session")
def crater(crater_file: Path) -> CraterMap:
    return CraterMap.load(crater_file)


@pytest.fixture
def lab(crater_file: Path, crater: CraterMap) -> Lab:
    return Lab.build(sim_settings(crater_file), crater)
