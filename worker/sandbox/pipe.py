"""The pipes to and from the planner process, both non-blocking and every wait with a
deadline: a planner that stops reading, or never answers, cannot block the runner."""

from __future__ import annotations

import os
import select
import time

from worker.sandbox.protocol import MAX_MESSAGE_BYTES


class StalledError(Exception):
    """The pipe to the planner process stayed full until the deadline."""


class ReadTimeoutError(Exception):
    """No whole message came before the deadline."""


class ClosedError(Exception):
    """The planner process closed its end: it is gone."""


class TooLargeError(Exception):
    """The planner process sent more than `MAX_MESSAGE_BYTES` without a line end."""


def write_all(fd: int, data: bytes, deadline: float) -> None:
    """Write all of `data` to non-blocking `fd` before `deadline`, else `StalledError`;
    `OSError` when the process is gone."""
    view = memoryview(data)
    poller = select.poll()
    poller.register(fd, select.POLLOUT)
    while view:
        try:
            view = view[os.write(fd, view):]
            continue
        except BlockingIOError:
            pass
        left = deadline - time.monotonic()
        if left <= 0:
            raise StalledError
        poller.poll(max(1, int(left * 1000)))


def read_line(fd: int, buffer: bytes, deadline: float) -> tuple[bytes, bytes]:
    """The next line (with its end) from `fd`, after what `buffer` holds, and what follows it;
    `ReadTimeoutError`, `ClosedError` or `TooLargeError` when there is none to be had."""
    poller = select.poll()
    poller.register(fd, select.POLLIN)
    while b"\n" not in buffer:
        left = deadline - time.monotonic()
        if left <= 0:
            raise ReadTimeoutError
        if not poller.poll(max(1, int(left * 1000))):
            continue
        chunk = os.read(fd, 1 << 20)
        if not chunk:
            raise ClosedError
        buffer += chunk
        if len(buffer) > MAX_MESSAGE_BYTES + 1:
            raise TooLargeError
    line, _, rest = buffer.partition(b"\n")
    return line + b"\n", rest
