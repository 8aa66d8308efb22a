"""Cross-cutting HTTP protections: security headers, CORS and rate limits.

Rate limits are token buckets per client (the bearer token's hash, else the address), kept in
the API process's memory: with several API processes each enforces its own share. They apply to
requests that change something and to failed authentications; reads are not limited, so that
pages and progress polling stay cheap.
"""

from __future__ import annotations

import hashlib
import threading
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass

from fastapi import FastAPI, Request, Response
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import JSONResponse

from server.settings import Settings

MUTATING = {"POST", "PUT", "PATCH", "DELETE"}
SECURITY_HEADERS = {
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
}


@dataclass
class _Bucket:
    tokens: float
    updated: float


class RateLimiter:
    """`rate_per_minute` requests per key, with bursts up to `burst`."""

    def __init__(self, rate_per_minute: float, burst: int) -> None:
        self.rate = rate_per_minute / 60.0
        self.burst = float(burst)
        self.buckets: dict[str, _Bucket] = {}
        self.lock = threading.Lock()

    def allow(self, key: str) -> float:
        """0 if allowed now, else the seconds to wait."""
        now = time.monotonic()
        with self.lock:
            bucket = self.buckets.get(key)
            if bucket is None:
                if len(self.buckets) > 100_000:  # forget idle clients rather than grow
                    self.buckets.clear()
                bucket = self.buckets[key] = _Bucket(self.burst, now)
            bucket.tokens = min(self.burst, bucket.tokens + (now - bucket.updated) * self.rate)
            bucket.updated = now
            if bucket.tokens >= 1.0:
                bucket.tokens -= 1.0
                return 0.0
            return (1.0 - bucket.tokens) / self.rate


def _client_key(request: Request) -> str:
    auth = request.headers.get("authorization", "")
    if auth:
        return "t:" + hashlib.sha256(auth.encode()).hexdigest()[:32]
    return "a:" + (request.client.host if request.client else "unknown")


def install_middleware(app: FastAPI, settings: Settings) -> None:
    writes = RateLimiter(settings.rate_limit_writes_per_minute, settings.rate_limit_burst)
    failures = RateLimiter(settings.rate_limit_auth_failures_per_minute,
                           settings.rate_limit_burst)

    @app.middleware("http")
    async def protect(request: Request,
                      call_next: Callable[[Request], Awaitable[Response]]) -> Response:
        host = "a:" + (request.client.host if request.client else "unknown")
        # A client that keeps failing to authenticate is slowed down, whatever it sends.
        if failures.buckets.get(host) is not None and failures.buckets[host].tokens < 1.0:
            wait = failures.allow(host)
            if wait > 0:
                return _too_many(wait, "too many failed authentications")
        if request.method in MUTATING and settings.rate_limit_writes_per_minute > 0:
            wait = writes.allow(_client_key(request))
            if wait > 0:
                return _too_many(wait, "too many requests that change data")
        response = await call_next(request)
        if response.status_code == 401:
            failures.allow(host)
        for name, value in SECURITY_HEADERS.items():
            response.headers.setdefault(name, value)
        return response

    if settings.cors_origins:
        app.add_middleware(CORSMiddleware, allow_origins=settings.cors_origins,
                           allow_methods=["GET", "POST"],
                           allow_headers=["Authorization", "Content-Type", "Idempotency-Key"],
                           allow_credentials=False, max_age=600)


def _too_many(wait: float, what: str) -> JSONResponse:
    seconds = max(1, int(wait + 0.999))
    return JSONResponse({"detail": f"rate limit: {what}; retry in {seconds} s"}, 429,
                        headers={"Retry-After": str(seconds), **SECURITY_HEADERS})
