"""Cross-cutting HTTP protections: security headers, CORS and rate limits.

Rate limits are token buckets per client (the bearer token's hash, else the address), held in
Redis when it is configured, so that all API processes enforce one limit per client, and in the
process's memory otherwise (`server.shared_state`). They apply to requests that change
something and to failed authentications; reads are not limited, so that pages and progress
polling stay cheap.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import JSONResponse

from server.settings import Settings
from server.shared_state import make_limiter

MUTATING = {"POST", "PUT", "PATCH", "DELETE"}
SECURITY_HEADERS = {
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
}
# As ASGI sends them, encoded once rather than on every answer.
_SECURITY_RAW = [(k.lower().encode(), v.encode()) for k, v in SECURITY_HEADERS.items()]


class Protect:
    """Security headers on every answer, and the rate limits (a plain ASGI middleware: the
    decorator form costs a task and a stream per request)."""

    def __init__(self, app: Any, settings: Settings) -> None:
        self.app = app
        self.settings = settings
        shared = settings.shared_redis_url
        self.writes = make_limiter(shared, "writes", settings.rate_limit_writes_per_minute,
                                   settings.rate_limit_burst)
        self.failures = make_limiter(shared, "auth-failures",
                                     settings.rate_limit_auth_failures_per_minute,
                                     settings.rate_limit_burst)
        self.local_failures = shared is None

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        client = scope.get("client")
        host = "a:" + (client[0] if client else "unknown")
        refused = await self._refusal(scope, host)
        if refused is not None:
            await refused(scope, receive, send)
            return
        failures = self.failures

        async def send_with_headers(message: Any) -> None:
            if message["type"] == "http.response.start":
                if message["status"] == 401:
                    await failures.wait(host)
                headers = message.get("headers", [])
                present = {k.lower() for k, _ in headers}
                extra = [kv for kv in _SECURITY_RAW if kv[0] not in present]
                message = {**message, "headers": [*headers, *extra]}
            await send(message)

        await self.app(scope, receive, send_with_headers)

    async def _refusal(self, scope: Any, host: str) -> JSONResponse | None:
        mutating = scope["method"] in MUTATING
        if not mutating and not self.local_failures:
            # Reads stay free of a Redis round trip; a client that keeps failing to
            # authenticate is stopped at its next write, or at its next read that needs a token.
            headers = dict(scope.get("headers") or [])
            if b"authorization" not in headers:
                return None
        # A client that keeps failing to authenticate is slowed down, whatever it sends.
        wait = await self.failures.wait(host, consume=False)
        if wait > 0:
            return _too_many(wait, "too many failed authentications")
        if mutating and self.settings.rate_limit_writes_per_minute > 0:
            headers = dict(scope.get("headers") or [])
            auth = headers.get(b"authorization", b"")
            key = ("t:" + hashlib.sha256(auth).hexdigest()[:32]) if auth else host
            wait = await self.writes.wait(key)
            if wait > 0:
                return _too_many(wait, "too many requests that change data")
        return None


def install_middleware(app: FastAPI, settings: Settings) -> None:
    app.add_middleware(Protect, settings=settings)
    slack = 256 * 1024  # multipart framing and form fields around the file
    app.add_middleware(
        BodyLimit,
        limits=[("/api/v1/areas", settings.max_area_upload_bytes + slack),
                ("/api/v1/planners",
                 int(settings.max_planner_upload_mib * 1024 * 1024) + slack)],
        default=1024 * 1024)
    if settings.cors_origins:
        app.add_middleware(CORSMiddleware, allow_origins=settings.cors_origins,
                           allow_methods=["GET", "POST"],
                           allow_headers=["Authorization", "Content-Type", "Idempotency-Key"],
                           allow_credentials=False, max_age=600)


def _too_many(wait: float, what: str) -> JSONResponse:
    seconds = max(1, int(wait + 0.999))
    return JSONResponse({"detail": f"rate limit: {what}; retry in {seconds} s"}, 429,
                        headers={"Retry-After": str(seconds), **SECURITY_HEADERS})


class BodyLimit:
    """Refuse request bodies over a size limit before they are parsed or spooled to disk.

    The declared Content-Length is checked first; a body without one (chunked) is counted as it
    arrives and cut off at the limit. Limits are per path prefix, the last entry the default.
    """

    def __init__(self, app: Any, limits: list[tuple[str, int]], default: int) -> None:
        self.app, self.limits, self.default = app, limits, default

    def _limit(self, path: str) -> int:
        for prefix, limit in self.limits:
            if path.startswith(prefix):
                return limit
        return self.default

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        if scope["type"] != "http" or scope["method"] not in MUTATING:
            await self.app(scope, receive, send)
            return
        limit = self._limit(scope["path"])
        headers = dict(scope.get("headers") or [])
        declared = headers.get(b"content-length")
        if declared is not None and (not declared.isdigit() or int(declared) > limit):
            await _send_413(send, limit)
            return
        seen = 0
        exceeded = False
        replaced = False

        async def counted_receive() -> Any:
            nonlocal seen, exceeded
            if exceeded:
                return {"type": "http.request", "body": b"", "more_body": False}
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > limit:
                    # Cut the body off here; whatever the app answers is replaced by a 413.
                    exceeded = True
                    return {"type": "http.request", "body": b"", "more_body": False}
            return message

        async def guarded_send(message: Any) -> None:
            nonlocal replaced
            if not exceeded:
                await send(message)
            elif not replaced and message["type"] == "http.response.start":
                replaced = True
                await _send_413(send, limit)

        await self.app(scope, counted_receive, guarded_send)


async def _send_413(send: Any, limit: int) -> None:
    body = json.dumps({"detail": f"request body too large: at most {limit} bytes"}).encode()
    await send({"type": "http.response.start", "status": 413,
                "headers": [(b"content-type", b"application/json"),
                            (b"content-length", str(len(body)).encode()),
                            *((k.lower().encode(), v.encode())
                              for k, v in SECURITY_HEADERS.items())]})
    await send({"type": "http.response.body", "body": body})
