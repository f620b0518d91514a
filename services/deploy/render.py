"""The router's access control and the compose services, from the lab file (pure).

A lab's PTZ cameras are its one variable part: each is a bus identity (its password, a rule
that lets it write only its own camera's keys, a subject and a policy in
``deploy/zenoh/router.json5``) and a compose service (``ptz-<n>``, its secret). Everything
else is fixed and lives in the templates next to this module. ``stb deploy render`` writes
both files; for the example lab they are the committed ones.
"""

from __future__ import annotations

import re
import textwrap
from dataclasses import dataclass
from importlib import resources
from string import Template

from common import keys

PREFIX = "stb"
FIXED_IDENTITIES = ("tracker", "gantry", "calib", "sim", "operator", "camera", "observation",
                    "monitor", "web")
ROUTER_CONFIG = "deploy/zenoh/router.json5"
COMPOSE_FILE = "docker-compose.yml"
_NAME = re.compile(r"^[a-z0-9][a-z0-9_-]*$")  # a compose service name and a Zenoh user name


class RenderError(ValueError):
    """The lab file cannot be rendered (the message names the field)."""


@dataclass(frozen=True)
class Camera:
    name: str  # the PTZ instance, its bus identity and its password file's name

    @property
    def service(self) -> str:
        """The compose service: ptz1 -> ptz-1, north -> ptz-north."""
        rest = self.name[3:] if self.name.startswith("ptz") and len(self.name) > 3 else self.name
        return f"ptz-{rest}"


def cameras_of(names: list[str]) -> list[Camera]:
    for name in names:
        if not _NAME.match(name):
            raise RenderError(f"ptz.cameras.{name}: a camera's name is its bus identity and "
                              "compose service: lower-case letters, digits, '-' and '_'")
        if name in FIXED_IDENTITIES:
            raise RenderError(f"ptz.cameras.{name}: the name of another identity")
    return [Camera(name) for name in names]


def router_config(cameras: list[Camera]) -> str:
    everyone = [*FIXED_IDENTITIES[:2], *(c.name for c in cameras), *FIXED_IDENTITIES[2:]]
    return _template("router.json5").substitute(
        camera_rules="".join(_camera_rule(c) for c in cameras),
        camera_subjects="".join(f'      {{ id: "{c.name}", usernames: ["{c.name}"] }},\n'
                                for c in cameras),
        everyone=_wrapped("subjects", everyone, indent=8),
        camera_policies="".join(f'      {{ rules: ["{c.name}"], subjects: ["{c.name}"] }},\n'
                                for c in cameras))


def compose_file(cameras: list[Camera]) -> str:
    return _template("docker-compose.yml").substitute(
        camera_services="".join(_camera_service(c) for c in cameras),
        camera_secrets="".join(f"  {c.name}-password: "
                               f"{{file: ./deploy/zenoh/secrets/{c.name}.password}}\n"
                               for c in cameras))


def _camera_rule(camera: Camera) -> str:
    own = [topic.key(PREFIX, camera=camera.name) for topic in
           (keys.PTZ_STATE, keys.PTZ_DETECTIONS, keys.PTZ_SNAPSHOT, keys.PTZ_PREVIEW)]
    own += [keys.HEALTH.key(PREFIX, service="ptz", instance=camera.name),
            keys.alive_key(PREFIX, "ptz", camera.name)]
    return (f'      {{ id: "{camera.name}", permission: "allow", flows: ["ingress"], '
            f'messages: ["put", "delete", "liveliness_token"],\n'
            f'{_wrapped("key_exprs", own, indent=8)} }},\n')


def _camera_service(camera: Camera) -> str:
    return f"""\
  {camera.service}:
    <<: *service
    command: ["ptz", "--instance", "{camera.name}"]
    ulimits: {{rtprio: 10}}  # realtime_priority = 10 allowed to user stb (docs/deployment.md §5)
    environment: {{<<: *bus, STB_BUS__ZENOH__USER: {camera.name}}}
    secrets: [{{source: ca, target: /run/secrets/ca.pem}},
              {{source: {camera.name}-password, target: /run/secrets/zenoh-password}}]

"""


def _wrapped(field: str, values: list[str], indent: int) -> str:
    """``field: ["a", "b", ...]`` over lines of at most 100 characters."""
    head = " " * indent + f"{field}: ["
    body = textwrap.fill(", ".join(f'"{v}"' for v in values), width=100 - len(head),
                         break_on_hyphens=False, break_long_words=False)
    lines = body.splitlines()
    pad = " " * len(head)
    return head + f"\n{pad}".join(lines) + "]"


def _template(name: str) -> Template:
    return Template((resources.files(__package__) / "templates" / name).read_text())
