"""The page as a console: what an operator does from it beside the gantry's buttons —
calibrate a camera (start, cancel, accept or discard the solved pose), hold a PTZ camera and
steer it by hand (move, presets, follow again), record the bus and open past reports.

Every action is a message on the bus as the signed-in operator (``Caller.label``), except
recordings, which run on the page's host (``recordings.py``). ``console_routes`` gives the
HTTP side; ``app.py`` guards each route (operators only, with the session's CSRF token).

    POST /calib/CAMERA/start|cancel|accept|discard
    POST /ptz/CAMERA/hold|follow|move|nudge|preset  {"pan_deg", "tilt_deg", "zoom"} | {"preset"}
    POST /record/start|stop                      {"seconds"} (start, optional)
    POST /doctor/run                             the lab check (``doctor_desk.py``)
    GET  /doctor.json                            its latest table
    GET  /recordings.json                        the recording under way and the past ones
    GET  /recordings/NAME/FILE                   a past recording's report (index.html, …)
"""

from __future__ import annotations

import logging
import time
from collections.abc import Awaitable, Callable
from typing import Any

import anyio
from pydantic import ValidationError
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response
from starlette.routing import Route

from common import keys
from common import messages as m
from common.bus import Bus
from services.web.doctor_desk import DoctorBusy, DoctorDesk
from services.web.gate import Caller
from services.web.recordings import DeskError, RecordingDesk

log = logging.getLogger(__name__)
CALIB_ACTIONS = ("start", "cancel", "accept", "discard")
HAND_ACTIONS = ("hold", "follow", "move", "nudge", "preset")
Guard = Callable[[Request], Awaitable[Caller | Response]]


class Console:
    def __init__(self, bus: Bus, desk: RecordingDesk, calibration_count: int = 100,
                 doctor: DoctorDesk | None = None) -> None:
        self.bus, self.desk, self.calibration_count = bus, desk, calibration_count
        self.doctor = doctor

    def calibrate(self, camera: str, action: str, by: str) -> dict[str, Any]:
        """A passpoint collection for ``camera``: started for an operator's review, or
        cancelled, accepted, discarded (the calib service answers on its progress key)."""
        self.bus.publish(keys.CALIB_COLLECT, m.CollectRequest.model_validate({
            "measured_s": time.time(), "camera": camera, "action": action,
            "count": self.calibration_count, "review": True}), camera=camera)
        log.info("calibration of %s: %s by %s", camera, action, by)
        return {"accepted": True, "detail": f"{action} sent to calib for {camera} as {by}"}

    def hand(self, camera: str, action: str, body: dict[str, Any], by: str) -> dict[str, Any]:
        """An operator's hand on a PTZ camera (its state says what it made of it)."""
        asked = {k: body[k] for k in ("pan_deg", "tilt_deg", "zoom", "preset") if k in body}
        hand = m.PtzHand.model_validate({"measured_s": time.time(), "camera": camera,
                                         "action": action, "operator": by, **asked})
        self.bus.publish(keys.PTZ_HAND, hand, camera=camera)
        log.info("%s: %s by %s", camera, action, by)
        return {"accepted": True, "detail": f"{action} sent to {camera}"}


def console_routes(console: Console, authorize: Guard,
                   signed_in: Callable[[Callable], Callable]) -> list[Route]:
    async def operator_of(request: Request, actions: tuple[str, ...]) -> Caller | Response:
        """The operator asking for one of ``actions``, or the answer to give (404, 401, 403)."""
        if request.path_params["action"] not in actions:
            return JSONResponse({"accepted": False, "detail": "no such action"}, 404)
        return await authorize(request)

    async def calib(request: Request) -> Response:
        action, camera = request.path_params["action"], request.path_params["camera"]
        caller = await operator_of(request, CALIB_ACTIONS)
        if isinstance(caller, Response):
            return caller
        return JSONResponse(console.calibrate(camera, action, caller.label))

    async def hand(request: Request) -> Response:
        action, camera = request.path_params["action"], request.path_params["camera"]
        caller = await operator_of(request, HAND_ACTIONS)
        if isinstance(caller, Response):
            return caller
        try:
            body = await request.json() if action in ("move", "nudge", "preset") else {}
            return JSONResponse(console.hand(camera, action, dict(body), caller.label))
        except (ValueError, TypeError, ValidationError) as err:
            return JSONResponse({"accepted": False, "detail": f"not a {action}: {err}"}, 400)

    async def record(request: Request) -> Response:
        action = request.path_params["action"]
        caller = await operator_of(request, ("start", "stop"))
        if isinstance(caller, Response):
            return caller
        try:
            if action == "start":
                body = await request.json() if await request.body() else {}
                seconds = float(body.get("seconds") or 0) or None
                answer = await anyio.to_thread.run_sync(console.desk.start, caller.label,
                                                        seconds)
            else:
                answer = await anyio.to_thread.run_sync(console.desk.stop, caller.label)
        except DeskError as err:
            return JSONResponse({"accepted": False, "detail": str(err)}, 409)
        except (ValueError, TypeError, AttributeError) as err:
            return JSONResponse({"accepted": False, "detail": f"bad request: {err}"}, 400)
        return JSONResponse({"accepted": True, **answer})

    async def recordings(request: Request) -> Response:
        return JSONResponse(await anyio.to_thread.run_sync(console.desk.view),
                            headers={"Cache-Control": "no-store"})

    async def report_file(request: Request) -> Response:
        path = console.desk.report_file(request.path_params["name"],
                                        request.path_params["file"])
        return Response("no such report", 404) if path is None else FileResponse(path)

    async def doctor_run(request: Request) -> Response:
        caller = await authorize(request)
        if isinstance(caller, Response):
            return caller
        if console.doctor is None:
            return JSONResponse({"accepted": False, "detail": "no lab check here"}, 404)
        try:
            return JSONResponse({"accepted": True, **console.doctor.start(caller.label)})
        except DoctorBusy as err:
            return JSONResponse({"accepted": False, "detail": str(err)}, 409)

    async def doctor_view(request: Request) -> Response:
        view = console.doctor.view() if console.doctor is not None else {"rows": []}
        return JSONResponse(view, headers={"Cache-Control": "no-store"})

    return [
        Route("/doctor/run", doctor_run, methods=["POST"]),
        Route("/doctor.json", signed_in(doctor_view)),
        Route("/calib/{camera:str}/{action:str}", calib, methods=["POST"]),
        Route("/ptz/{camera:str}/{action:str}", hand, methods=["POST"]),
        Route("/record/{action:str}", record, methods=["POST"]),
        Route("/recordings.json", signed_in(recordings)),
        Route("/recordings/{name:str}/{file:str}", signed_in(report_file)),
    ]
