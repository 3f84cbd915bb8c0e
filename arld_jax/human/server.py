"""The demonstration page's HTTP server: a Starlette app served by uvicorn in a thread of the
training process, bound to 127.0.0.1 only.

    GET  /                  the page (web/demonstrate.html, web/demonstrate.js)
    POST /api/session       register this tab -> {"token"}; a second tab gets 409 unless it sends
                            {"take_over": true} (then the first tab's requests get 403)
    GET  /api/state         the run, its progress and the pending step (frames, agent's action, u(s))
    POST /api/action        {"step_id", "action": [A numbers in [-1, 1]]}
    POST /api/hand_back     {"step_id"}: the rest of this query is the agent's
    POST /api/pause         {"paused": bool}

Every /api request but /api/session carries the token in the `X-Demo-Session` header. Refusals are
JSON {"error", "allowed"} with a 4xx status, and change nothing. Host headers other than
127.0.0.1/localhost are refused (a page elsewhere cannot reach the server by DNS rebinding).
"""

from __future__ import annotations

import socket
import threading
import time
from importlib import resources
from typing import Any

from starlette.applications import Starlette
from starlette.middleware import Middleware
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Route

from arld_jax.human.session import TOKEN_HEADER, DemoSession, RequestError, parse_json_object

HOST = "127.0.0.1"
WEB_FILES = {
    "/": ("demonstrate.html", "text/html"),
    "/demonstrate.js": ("demonstrate.js", "text/javascript"),
}


def web_asset(name: str) -> bytes:
    """A static file of the page, shipped as package data (arld_jax/human/web/)."""
    return (resources.files("arld_jax.human") / "web" / name).read_bytes()


def make_app(session: DemoSession) -> Starlette:
    """The ASGI app of `session`."""

    def static(name: str, media_type: str):  # noqa: ANN202
        async def endpoint(request: Request) -> Response:
            return Response(
                web_asset(name), media_type=media_type, headers={"Cache-Control": "no-store"}
            )

        return endpoint

    def api(method):  # noqa: ANN001, ANN202
        """An endpoint calling session.method(token, body) (or (body) for registration)."""

        async def endpoint(request: Request) -> JSONResponse:
            try:
                token = request.headers.get(TOKEN_HEADER)
                if request.method == "GET":
                    result = method(token)
                else:
                    body = parse_json_object(await request.body())
                    result = method(body) if method == session.register else method(token, body)
            except RequestError as err:
                return JSONResponse(err.body(), status_code=err.status)
            return JSONResponse(result, headers={"Cache-Control": "no-store"})

        return endpoint

    routes = [Route(path, static(*spec)) for path, spec in WEB_FILES.items()]
    routes += [
        Route("/api/session", api(session.register), methods=["POST"]),
        Route("/api/state", api(session.snapshot), methods=["GET"]),
        Route("/api/action", api(session.submit), methods=["POST"]),
        Route("/api/hand_back", api(session.hand_back), methods=["POST"]),
        Route("/api/pause", api(session.set_paused), methods=["POST"]),
    ]
    middleware = [Middleware(TrustedHostMiddleware, allowed_hosts=[HOST, "localhost"])]
    return Starlette(routes=routes, middleware=middleware)


class ServerThread:
    """uvicorn serving `app` on 127.0.0.1:`port` (0 = any free port) in a daemon thread."""

    def __init__(self, app: Any, port: int = 8765) -> None:
        import uvicorn

        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.sock.bind((HOST, port))
        except OSError as err:
            self.sock.close()
            raise SystemExit(
                f"error: cannot listen on {HOST}:{port} ({err.strerror}); choose another --port"
            ) from None
        self.port = self.sock.getsockname()[1]
        # Listen now: a browser connecting before uvicorn's thread runs (the training thread may
        # hold the interpreter for a while, compiling) waits in the backlog instead of being refused.
        self.sock.listen(64)
        config = uvicorn.Config(app, log_level="warning", lifespan="off")
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(
            target=self.server.run, kwargs={"sockets": [self.sock]}, daemon=True, name="demo-server"
        )

    @property
    def url(self) -> str:
        return f"http://{HOST}:{self.port}/"

    def start(self, timeout: float = 60.0) -> ServerThread:
        """Start serving; return once uvicorn accepts connections (or after `timeout` seconds)."""
        self.thread.start()
        deadline = time.monotonic() + timeout
        while not self.server.started and self.thread.is_alive() and time.monotonic() < deadline:
            time.sleep(0.02)
        return self

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=10)
        self.sock.close()
