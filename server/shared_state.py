"""What the API processes share: the rate limits' token buckets and the results epoch.

With Redis configured (`Settings.shared_redis_url`) both live there, so that N API processes
enforce one rate limit per client and agree on when the cached leaderboards went stale. On the
embedded default (one API process, no Redis) the buckets live in the process and the
leaderboard checks the database instead of an epoch.

Redis failing never fails a request: a rate limit that cannot be read lets the request through
(logged), and the leaderboard falls back to its database check.
"""

from __future__ import annotations

import asyncio
import logging
import os
import secrets
import threading
import time
from dataclasses import dataclass
from typing import Any, Protocol

import redis
import redis.asyncio as aioredis

log = logging.getLogger(__name__)

KEY_PREFIX = "flybo:"
EPOCH_KEY = KEY_PREFIX + "results-epoch"
_TIMEOUT_S = 0.5

# One token bucket per key, refilled at `rate` per second up to `burst`; the wait is returned
# as a string (Redis turns Lua numbers into integers). `consume` 0 only looks.
_BUCKET = """
local rate, burst, consume = tonumber(ARGV[1]), tonumber(ARGV[2]), tonumber(ARGV[3])
local t = redis.call('TIME')
local now = tonumber(t[1]) + tonumber(t[2]) / 1000000
local b = redis.call('HMGET', KEYS[1], 'tokens', 'updated')
local tokens = tonumber(b[1]) or burst
local updated = tonumber(b[2]) or now
tokens = math.min(burst, tokens + math.max(0, now - updated) * rate)
local wait = 0
if tokens >= 1 then
  if consume == 1 then tokens = tokens - 1 end
else
  wait = (1 - tokens) / rate
end
redis.call('HSET', KEYS[1], 'tokens', tostring(tokens), 'updated', tostring(now))
redis.call('PEXPIRE', KEYS[1], math.ceil(burst / rate * 1000) + 1000)
return tostring(wait)
"""


class Limiter(Protocol):
    async def wait(self, key: str, consume: bool = True) -> float:
        """0 if a request of `key` may go now (taking a token when `consume`), else the
        seconds until it may."""
        ...


@dataclass
class _Bucket:
    tokens: float
    updated: float


class LocalLimiter:
    """Token buckets in this process's memory: `rate_per_minute` per key, bursts up to
    `burst`."""

    def __init__(self, rate_per_minute: float, burst: int) -> None:
        self.rate = rate_per_minute / 60.0
        self.burst = float(burst)
        self.buckets: dict[str, _Bucket] = {}
        self.lock = threading.Lock()

    def take(self, key: str, consume: bool = True) -> float:
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
                bucket.tokens -= 1.0 if consume else 0.0
                return 0.0
            return (1.0 - bucket.tokens) / self.rate

    async def wait(self, key: str, consume: bool = True) -> float:
        return self.take(key, consume)


class RedisLimiter:
    """The same buckets in Redis, one per key for all API processes (a Lua script: each
    check is one atomic round trip)."""

    def __init__(self, url: str, name: str, rate_per_minute: float, burst: int) -> None:
        self.url, self.prefix = url, f"{KEY_PREFIX}rate:{name}:"
        self.rate, self.burst = rate_per_minute / 60.0, float(burst)
        # A client per event loop: an asyncio connection belongs to the loop that opened it.
        self._clients: dict[int, tuple[asyncio.AbstractEventLoop, Any, Any]] = {}
        self._warned = 0.0

    def _script(self) -> Any:
        loop = asyncio.get_running_loop()
        held = self._clients.get(id(loop))
        if held is None or held[0] is not loop:
            client = aioredis.Redis.from_url(self.url, socket_timeout=_TIMEOUT_S,
                                              socket_connect_timeout=_TIMEOUT_S)
            held = self._clients[id(loop)] = (loop, client, client.register_script(_BUCKET))
        return held[2]

    async def wait(self, key: str, consume: bool = True) -> float:
        try:
            answer = await self._script()(keys=[self.prefix + key],
                                          args=[self.rate, self.burst, int(consume)])
        except (redis.RedisError, OSError) as exc:
            now = time.monotonic()
            if now - self._warned > 60:  # once a minute, not once a request
                self._warned = now
                log.warning("rate limit not checked, Redis unavailable: %s", exc)
            return 0.0
        return float(answer)


def make_limiter(redis_url: str | None, name: str, rate_per_minute: float,
                 burst: int) -> Limiter:
    if redis_url is None:
        return LocalLimiter(rate_per_minute, burst)
    return RedisLimiter(redis_url, name, rate_per_minute, burst)


_sync_clients: dict[tuple[int, str], redis.Redis] = {}
_sync_lock = threading.Lock()


def _client(url: str) -> redis.Redis:
    """One thread-safe client per process and URL (a fork gets its own)."""
    key = (os.getpid(), url)
    with _sync_lock:
        client = _sync_clients.get(key)
        if client is None:
            client = _sync_clients[key] = redis.Redis.from_url(
                url, socket_timeout=_TIMEOUT_S, socket_connect_timeout=_TIMEOUT_S)
        return client


def _start_epoch(client: redis.Redis) -> None:
    # A random start: should Redis lose the key, counting restarts elsewhere, and no API
    # process mistakes the new epochs for one its cached boards were computed at.
    client.set(EPOCH_KEY, secrets.randbelow(1 << 40) + 1, nx=True)


def read_results_epoch(url: str) -> int | None:
    """The results epoch (bumped whenever stored results change), or None if Redis does not
    answer."""
    try:
        client = _client(url)
        value = client.get(EPOCH_KEY)
        if value is None:
            _start_epoch(client)
            value = client.get(EPOCH_KEY)
    except (redis.RedisError, OSError) as exc:
        log.debug("results epoch not read: %s", exc)
        return None
    return int(value) if value is not None else None


def bump_results_epoch(url: str) -> None:
    """Tell every API process that stored results changed; after the change is committed."""
    try:
        client = _client(url)
        _start_epoch(client)
        client.incr(EPOCH_KEY)
    except (redis.RedisError, OSError) as exc:
        # The API's sweep notices the change in the database within an interval.
        log.warning("results epoch not bumped (Redis unavailable): %s", exc)


class EpochNet:
    """The sweep's safety net: bump the epoch when the stored results changed without it (a
    writer without Redis, a lost bump), as the database's results version shows."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.seen: object = None

    def check(self, version: object) -> bool:
        """Bump if `version` differs from the last one seen; whether it bumped."""
        changed = self.seen is not None and version != self.seen
        self.seen = version
        if changed:
            bump_results_epoch(self.url)
        return changed
