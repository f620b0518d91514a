"""The page's HTTP side (Starlette): sign-in, the page, its live state, pictures and commands.

    GET  /                the page when signed in, else the sign-in form
    POST /signin          {"user", "password"} → a session cookie; /signout ends it
    GET  /session.json    who is signed in, their role and the CSRF token commands need
    GET  /state.json      the state once          GET /events   text/event-stream of the state
    GET  /map.json        height map extent (mm)  GET /map.png  the height map
    GET  /preview/CAMERA.jpg                      a camera's latest preview
    GET  /video/CAMERA.jpg                        a camera's latest video frame (the
                                                  observation camera's bird's-eye view)
    POST /gantry/arm|disarm|stop|reset            an operator's command; the gantry's answer

Everything but the sign-in form and its script needs a signed-in session or HTTP Basic with a
user of the users file (``gate.py``): 401 otherwise; commands need an operator (403 for a
viewer) and, from the page, the session's CSRF token in ``X-CSRF-Token``.
"""

from __future__ import annotations

import asyncio
import json
import logging
import re
from collections.abc import AsyncIterator, Awaitable, Callable
from importlib import resources
from typing import Any

import anyio
from starlette.applications import Starlette
from starlette.middleware import Middleware
from starlette.requests import Request
from starlette.responses import JSONResponse, Response, StreamingResponse
from starlette.routing import Route

from common.names import GANTRY_COMMANDS
from common.settings import NAME_PATTERN
from services.web.console import Console, console_routes
from services.web.crater_image import CraterImage
from services.web.gate import COOKIE, Caller, Gate, command_refusal
from services.web.hosts import HostCheck, HostGate
from services.web.lanes import Busy, command_lane, password_lane
from services.web.limits import BodyLimit

log = logging.getLogger(__name__)
CAMERA = re.compile(NAME_PATTERN)
STATIC = {"index.html": "text/html; charset=utf-8", "app.js": "text/javascript; charset=utf-8",
          "signin.html": "text/html; charset=utf-8",
          "signin.js": "text/javascript; charset=utf-8"}
NO_STORE = {"Cache-Control": "no-store"}


def _static(name: str) -> Response:
    body = resources.files("services.web").joinpath("static", name).read_bytes()
    return Response(body, media_type=STATIC[name], headers=NO_STORE)


class LiveView:
    """The state as JSON, made once per push period for every open event stream."""

    def __init__(self, view: Callable[[], dict[str, Any]], period_s: float,
                 max_streams: int) -> None:
        self.view, self.period_s, self.max_streams = view, period_s, max_streams
        self.streams = 0
        self._latest = b""
        self._fresh = asyncio.Event()
        self._task: asyncio.Task | None = None

    async def _refresh(self) -> None:
        while True:
            self._latest = json.dumps(await anyio.to_thread.run_sync(self.view)).encode()
            fresh, self._fresh = self._fresh, asyncio.Event()
            fresh.set()
            await asyncio.sleep(self.period_s)

    async def stream(self) -> AsyncIterator[bytes]:
        if self._task is None or self._task.done():
            self._task = asyncio.get_running_loop().create_task(self._refresh())
        self.streams += 1
        try:
            if self._latest:
                yield b"data: " + self._latest + b"\n\n"
            while True:
                await self._fresh.wait()
                yield b"data: " + self._latest + b"\n\n"
        finally:
            self.streams -= 1


def build_app(gate: Gate, view: Callable[[], dict[str, Any]],
              preview: Callable[[str], bytes | None],
              video: Callable[[str], bytes | None], crater: CraterImage, *,
              push_period_s: float, max_streams: int,
              command: Callable[[str, str], dict] | None = None,
              console: Console | None = None, hosts: HostCheck | None = None) -> Starlette:
    """The page's application; ``command(name, caller_label)`` sends a gantry command;
    ``console``: the calibration, camera and recording controls (``console.py``);
    ``hosts``: the names it answers to (``hosts.py``; None: any)."""
    live = LiveView(view, push_period_s, max_streams)
    passwords, commands = password_lane(), command_lane()

    async def who(request: Request) -> Caller | None:
        """The caller: at once from a session, or after a password check in its lane."""
        address = request.client.host if request.client else "?"
        asked = (request.cookies.get(COOKIE), request.headers.get("authorization"), address)
        known, needs_check = gate.caller_at_once(*asked)
        return await passwords.run(gate.caller, *asked) if needs_check else known

    async def busy(request: Request, exc: Exception) -> Response:
        assert isinstance(exc, Busy)
        return JSONResponse({"accepted": False, "detail": exc.detail}, 503, headers={
            "Retry-After": str(int(exc.retry_after_s + 0.999)), **NO_STORE})

    def unauthorised() -> Response:
        return JSONResponse({"detail": "sign in first"}, status_code=401, headers={
            "WWW-Authenticate": 'Basic realm="STB Supervisor", charset="UTF-8"', **NO_STORE})

    def signed_in(handler: Callable[[Request], Any]) -> Callable[[Request], Any]:
        async def guarded(request: Request) -> Response:
            if await who(request) is None:
                return unauthorised()
            return await handler(request)
        return guarded

    async def page(request: Request) -> Response:
        caller = await who(request)
        return _static("signin.html" if caller is None else "index.html")

    async def static(request: Request) -> Response:
        return _static(request.url.path.lstrip("/"))

    async def session_info(request: Request) -> Response:
        caller = await who(request)
        if caller is None:
            return unauthorised()
        return JSONResponse({"user": caller.user.name, "role": str(caller.user.role),
                             "may_command": caller.user.may_command, "csrf": caller.csrf,
                             "open": gate.is_open}, headers=NO_STORE)

    async def sign_in(request: Request) -> Response:
        if request.headers.get("content-type", "").split(";")[0] != "application/json":
            return JSONResponse({"detail": "send JSON (Content-Type: application/json)"}, 415)
        try:
            asked = await request.json()
            name, password = str(asked["user"]), str(asked["password"])
        except (ValueError, KeyError, TypeError):
            return JSONResponse({"detail": 'send {"user": ..., "password": ...}'}, 400)
        address = request.client.host if request.client else "?"
        outcome = await passwords.run(gate.sign_in, name, password, address)
        headers = dict(NO_STORE)
        if outcome.retry_after_s:
            headers["Retry-After"] = str(int(outcome.retry_after_s + 1))
        reply = JSONResponse({"detail": outcome.detail}, outcome.status, headers=headers)
        if outcome.token and outcome.session:
            reply.set_cookie(COOKIE, outcome.token, max_age=int(gate.sessions.lifetime_s),
                             httponly=True, samesite="strict", secure=gate.tls, path="/")
        return reply

    async def sign_out(request: Request) -> Response:
        gate.sign_out(request.cookies.get(COOKIE))
        reply = JSONResponse({"detail": "signed out"}, headers=NO_STORE)
        reply.delete_cookie(COOKIE, path="/", httponly=True, samesite="strict", secure=gate.tls)
        return reply

    async def state(request: Request) -> Response:
        return JSONResponse(await anyio.to_thread.run_sync(view), headers=NO_STORE)

    async def events(request: Request) -> Response:
        if live.streams >= live.max_streams:
            return JSONResponse({"detail": f"{live.streams} live views open already: close "
                                 "one, or use /state.json"}, 503, headers={"Retry-After": "5"})
        return StreamingResponse(live.stream(), media_type="text/event-stream",
                                 headers=NO_STORE)

    async def map_info(request: Request) -> Response:
        info, _ = await anyio.to_thread.run_sync(crater.get)
        return Response(info, media_type="application/json", headers=NO_STORE)

    async def map_png(request: Request) -> Response:
        _, png = await anyio.to_thread.run_sync(crater.get)
        if png is None:
            return Response("no height map yet", 404)
        return Response(png, media_type="image/png", headers=NO_STORE)

    def camera_jpeg(latest: Callable[[str], bytes | None], missing: str
                    ) -> Callable[[Request], Awaitable[Response]]:
        """A route answering a camera's latest JPEG (``latest(camera)``), 404 without."""
        async def answer(request: Request) -> Response:
            camera = request.path_params["camera"]
            jpeg = latest(camera) if CAMERA.match(camera) else None
            if jpeg is None:
                return Response(missing, 404)
            return Response(jpeg, media_type="image/jpeg", headers=NO_STORE)
        return answer

    async def authorize(request: Request) -> Caller | Response:
        """The operator behind a command, or the refusal (401, 403) to answer with."""
        caller = await who(request)
        refusal = command_refusal(caller, request.headers.get("x-csrf-token"),
                                  request.headers.get("origin"), request.headers.get("host"))
        if refusal is None:
            assert caller is not None
            return caller
        if caller is not None:
            log.warning("%s from %s refused: %s", request.url.path, caller.label, refusal[1])
        return JSONResponse({"accepted": False, "detail": refusal[1]}, refusal[0])

    async def gantry_command(request: Request) -> Response:
        name = request.path_params["command"]
        if name not in GANTRY_COMMANDS or command is None:
            return Response("no such command", 404)
        caller = await authorize(request)
        if isinstance(caller, Response):
            return caller
        answer = await commands.run(command, name, caller.label)
        log.info("command %s by %s: %s (%s)", name, caller.label,
                 "accepted" if answer.get("accepted") else "refused", answer.get("detail"))
        return JSONResponse(answer, headers=NO_STORE)

    routes = [
        Route("/", page), Route("/signin.js", static), Route("/signin", sign_in,
                                                             methods=["POST"]),
        Route("/signout", sign_out, methods=["POST"]),
        Route("/session.json", session_info),
        Route("/app.js", signed_in(static)), Route("/state.json", signed_in(state)),
        Route("/events", signed_in(events)), Route("/map.json", signed_in(map_info)),
        Route("/map.png", signed_in(map_png)),
        Route("/preview/{camera}.jpg", signed_in(camera_jpeg(preview, "no such preview"))),
        Route("/video/{camera}.jpg", signed_in(camera_jpeg(video, "no video from that camera"))),
        Route("/gantry/{command}", gantry_command, methods=["POST"]),
    ]
    if console is not None:
        routes += console_routes(console, authorize, signed_in)
    middleware = ([] if hosts is None else [Middleware(HostGate, check=hosts)]) + \
        [Middleware(BodyLimit)]
    return Starlette(routes=routes, exception_handlers={Busy: busy}, middleware=middleware)
