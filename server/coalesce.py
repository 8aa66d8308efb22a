"""Concurrent reads of one thing, answered by one query per batch, without serving stale data.

A request needs a read that started after it arrived (what a query of its own would give).
Requests that arrive while a read of the same key runs wait for the next one, which starts as
soon as that read ends and answers all of them: 200 clients polling one job cost one query
per round trip of the database, not 200. The leaderboard's version check
(`server.leaderboard._Gate`) uses it too.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Generic, TypeVar

K = TypeVar("K")
V = TypeVar("V")


class _Batch(Generic[V]):
    def __init__(self) -> None:
        self.waiters: list[asyncio.Future[V]] = []
        self.task: asyncio.Task[None] | None = None


class Coalesced(Generic[K, V]):
    """`await reads.get(key)`: `read(key)` in a worker thread, shared by the requests that
    waited for the same read."""

    def __init__(self, read: Callable[[K], V]) -> None:
        self.read = read
        self.loop: asyncio.AbstractEventLoop | None = None
        self.batches: dict[K, _Batch[V]] = {}

    async def get(self, key: K, read: Callable[[K], V] | None = None) -> V:
        """The value of a read of `key` that started after this call; `read`, if given, is
        used in place of the constructor's when this call starts the read (callers sharing a
        key must pass equivalent reads)."""
        loop = asyncio.get_running_loop()
        if self.loop is not loop:  # a new event loop (tests): nothing carries over
            self.loop, self.batches = loop, {}
        batch = self.batches.get(key)
        if batch is None:
            batch = self.batches[key] = _Batch()
        waiter: asyncio.Future[V] = loop.create_future()
        batch.waiters.append(waiter)
        if batch.task is None:
            batch.task = loop.create_task(self._drain(key, batch, read or self.read))
        return await waiter

    async def _drain(self, key: K, batch: _Batch[V], read: Callable[[K], V]) -> None:
        try:
            while batch.waiters:
                waiters, batch.waiters = batch.waiters, []
                try:
                    value = await asyncio.to_thread(read, key)
                except Exception as exc:
                    for w in waiters:
                        if not w.done():
                            w.set_exception(exc)
                else:
                    for w in waiters:
                        if not w.done():
                            w.set_result(value)
        finally:
            batch.task = None
            if not batch.waiters and self.batches.get(key) is batch:
                del self.batches[key]  # forget keys nobody asks for now
