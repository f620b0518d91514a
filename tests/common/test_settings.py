"""Settings: defaults < lab file < environment < flags; errors name the field."""

from __future__ import annotations

from pathlib import Path

import pytest

from common.errors import ConfigError
from common.settings import load_settings
from services.args import base_parser, overrides_from
from services.router.settings import RouterSettings
from services.supervisor import UpSettings


def _lab(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "lab.toml"
    path.write_text(text)
    return path


def test_defaults_run_against_loopback() -> None:
    s = load_settings(RouterSettings, environ={})
    assert s.bus.prefix == "stb"
    assert s.bus.zenoh.connect == ["tcp/127.0.0.1:7447"]
    assert s.bus.zenoh.multicast_scouting is False
    assert s.zenoh_settings().listen == ["tcp/127.0.0.1:7447"]


def test_precedence_file_then_env_then_flags(tmp_path: Path) -> None:
    lab = _lab(tmp_path, """
[bus]
prefix = "lab"
max_age_s = 0.3
[bus.zenoh]
connect = ["tcp/10.0.0.1:7447"]
[router]
instance = "from-file"
log_level = "DEBUG"
[router.bus]
max_age_s = 0.4
""")
    env = {"STB_ROUTER__INSTANCE": "from-env", "STB_BUS__ZENOH__LEASE_MS": "3000",
           "STB_ROUTER__LISTEN": '["tcp/0.0.0.0:7447"]'}
    s = load_settings(RouterSettings, lab, {"log_level": "ERROR"}, environ=env)
    assert s.bus.prefix == "lab"                       # shared [bus]
    assert s.bus.max_age_s == 0.4                      # [router.bus] beats [bus]
    assert s.bus.zenoh.connect == ["tcp/10.0.0.1:7447"]
    assert s.bus.zenoh.lease_ms == 3000                # STB_BUS__ env
    assert s.instance == "from-env"                    # env beats file
    assert s.listen == ["tcp/0.0.0.0:7447"]            # JSON env value
    assert s.log_level == "ERROR"                      # flags beat everything


def test_lab_file_named_by_environment(tmp_path: Path) -> None:
    lab = _lab(tmp_path, '[router]\ninstance = "r2"\n')
    assert load_settings(RouterSettings, environ={"STB_LAB": str(lab)}).instance == "r2"


@pytest.mark.parametrize(("text", "env", "field"), [
    ('[router]\nlisten = 5\n', {}, "router.listen"),
    ('[router]\nlisen = ["tcp/x:1"]\n', {}, "router.lisen"),
    ('[bus]\nprefix = "Bad/*"\n', {}, "router.bus.prefix"),
    ('[bus.zenoh]\nmode = "clinet"\n', {}, "router.bus.zenoh.mode"),
    ('[bus.zenoh]\nconnect = ["127.0.0.1:7447"]\n', {}, "router.bus.zenoh.connect"),
    ("", {"STB_ROUTER__BUS__MAX_AGE_S": "-1"}, "router.bus.max_age_s"),
])
def test_bad_setting_names_the_field(tmp_path: Path, text: str, env: dict, field: str) -> None:
    with pytest.raises(ConfigError) as err:
        load_settings(RouterSettings, _lab(tmp_path, text), environ=env)
    assert field in str(err.value)


def test_unreadable_or_invalid_lab_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        load_settings(RouterSettings, tmp_path / "missing.toml", environ={})
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_settings(RouterSettings, _lab(tmp_path, "[router\n"), environ={})


def test_up_refuses_unknown_services() -> None:
    with pytest.raises(ConfigError, match="unknown service 'gantri'"):
        load_settings(UpSettings, overrides={"services": ["router", "gantri"]}, environ={})


def test_example_lab_file_is_valid_for_every_service() -> None:
    from services.registry import SERVICES, TOOLS, settings_class

    example = Path(__file__).resolve().parents[2] / "config" / "lab.example.toml"
    for info in [*SERVICES.values(), *TOOLS.values()]:
        if info.settings:
            load_settings(settings_class(info), example, environ={})


@pytest.mark.parametrize(("text", "field", "why"), [
    ("[gantry]\nx_min_mm = 3000\nx_max_mm = -3000\n", "gantry.x_max_mm", "greater than x_min_mm"),
    ("[gantry]\ny_max_mm = -3000\n", "gantry.y_max_mm", "greater than y_min_mm"),
    ("[gantry]\nx_min_mm = -40\nx_max_mm = 40\n", "gantry.workspace_margin_mm", "no workspace"),
    ("[sim.crane]\nx_max_mm = -3500\n", "sim.crane.x_max_mm", "greater than x_min_mm"),
    ("[tracker.volume]\nz_min_mm = 5000\n", "tracker.volume", "z_max_mm (4000) must be greater"),
])
def test_an_interval_upside_down_is_refused_naming_the_field(tmp_path: Path, text: str,
                                                             field: str, why: str) -> None:
    """An inverted workspace used to pass, and its clamp then sent every setpoint to
    −3050 mm, beyond the crane's travel."""
    from services.registry import SERVICES, settings_class

    section = field.split(".")[0]
    with pytest.raises(ConfigError) as err:
        load_settings(settings_class(SERVICES[section]), _lab(tmp_path, text), environ={})
    assert field in str(err.value) and why in str(err.value), str(err.value)


def test_a_binary_lab_file_is_named_not_a_traceback(tmp_path: Path) -> None:
    path = tmp_path / "lab.toml"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff\xfe")
    with pytest.raises(ConfigError, match=f"lab config {path} is not valid TOML: not UTF-8"):
        load_settings(RouterSettings, path, environ={})



@pytest.mark.parametrize(("field", "text", "expected"), [
    ("instance", "7", "7"),  # a name: the environment's "7", the flag's once a number
    ("instance", "true", "true"),
    ("bus.max_age_s", "0.2", 0.2),
    ("listen", '["tcp/127.0.0.1:7447"]', ["tcp/127.0.0.1:7447"]),
    ("log_level", "null", ConfigError),  # none: no log level, refused alike
])
def test_a_flag_and_the_environment_read_a_value_alike(field: str, text: str,
                                                        expected: object) -> None:
    """``--set FIELD=VALUE`` and ``STB_ROUTER__FIELD=VALUE`` give the same setting."""
    flags = overrides_from(base_parser("stb router", "").parse_args(["--set", f"{field}={text}"]))
    env = {"STB_ROUTER__" + field.upper().replace(".", "__"): text}
    if expected is ConfigError:
        for overrides, environ in ((flags, {}), ({}, env)):
            with pytest.raises(ConfigError, match=field):
                load_settings(RouterSettings, None, overrides, environ=environ)
        return
    by_flag = load_settings(RouterSettings, None, flags, environ={})
    by_env = load_settings(RouterSettings, None, {}, environ=env)
    read = (lambda s: s.bus.max_age_s) if field == "bus.max_age_s" else (
        lambda s: getattr(s, field))
    assert (read(by_flag), read(by_env)) == (expected, expected)
