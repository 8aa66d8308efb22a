"""What the sandbox tests need from the machine: full isolation (and, for some, the seccomp
filter). Missing, a test skips saying why, or fails under CI=true, where it must be there."""

from __future__ import annotations

import os

import pytest

from worker.sandbox.isolation import probe


def required(message: str) -> None:
    """Skip with `message`, or fail with it under CI=true."""
    if os.environ.get("CI") == "true":
        pytest.fail(message)
    pytest.skip(message)


@pytest.fixture(scope="module")
def isolated() -> None:
    iso = probe()
    if not iso.full:
        required(f"full isolation is not available here: {'; '.join(iso.notes)}")
