"""Request bodies bounded before anything reads them (ASGI middleware): the page's requests
are small JSON (a sign-in, a command, a recording's length), so a body declared larger than
``MAX_BODY`` is refused 413 at once, and one that grows past it while it streams (chunked)
is cut off with 413. Three anonymous 500 MB bodies to ``/signin`` once took the web process
to 2.14 GB, 588 MB of it kept. (Headers are bounded by uvicorn's parser: 16 KiB.)"""

from __future__ import annotations

from starlette.responses import PlainTextResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

MAX_BODY = 64 * 1024


class BodyTooLarge(Exception):
    pass


class BodyLimit:
    def __init__(self, app: ASGIApp, limit: int = MAX_BODY) -> None:
        self.app, self.limit = app, limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = next((v for k, v in scope.get("headers", []) if k == b"content-length"),
                        None)
        if declared is not None and (not declared.strip().isdigit()
                                     or int(declared) > self.limit):
            await self._refuse(scope, receive, send)
            return
        seen = 0
        started = False

        async def counted() -> Message:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.limit:
                    raise BodyTooLarge
            return message

        async def sending(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, counted, sending)
        except BodyTooLarge:
            if not started:
                await self._refuse(scope, receive, send)

    async def _refuse(self, scope: Scope, receive: Receive, send: Send) -> None:
        response = PlainTextResponse(f"request body larger than {self.limit} bytes", 413,
                                     headers={"Connection": "close"})
        await response(scope, receive, send)
