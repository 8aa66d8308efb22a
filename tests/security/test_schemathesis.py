"""Property-based requests generated from our own OpenAPI schema: no answer may be a 5xx.

At least 2,000 requests over every operation, with and without a valid token (rate limits off,
so that generated writes reach the handlers)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import schemathesis
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from sqlalchemy.orm import Session, sessionmaker

from server.app import create_app
from server.db import session_scope
from server.security import create_token
from server.settings import Settings

EXAMPLES_PER_OPERATION = 160


@pytest.fixture(scope="module")
def fuzz_app(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Any, str]]:
    root: Path = tmp_path_factory.mktemp("fuzz")
    config = Settings(data_dir=root / "data", rate_limit_writes_per_minute=0,
                      rate_limit_auth_failures_per_minute=1e9, quota_jobs_per_day=0,
                      quota_concurrent_runs=0, max_runs_per_job=4)
    app = create_app(config, sweeper=False, sync_areas=False)
    with TestClient(app) as client:  # runs the start-up: migrations, planners
        from server.db import make_engine, make_session_factory

        engine = make_engine(config.db_url)
        factory: sessionmaker[Session] = make_session_factory(engine)
        with session_scope(factory) as session:
            token = create_token(session, "fuzzer", config.secret_key)
        client.get("/api/v1/areas/maze")  # one area row for the reads
        yield app, token
        engine.dispose()


def test_no_server_errors(fuzz_app: tuple[Any, str]) -> None:
    app, token = fuzz_app
    schema = schemathesis.openapi.from_asgi("/openapi.json", app)
    sent: list[tuple[str, int]] = []
    operations = [result.ok() for result in schema.get_all_operations()]
    assert len(operations) >= 15
    for operation in operations:
        _fuzz(operation, token, sent)
    per_operation = {label for label, _ in sent}
    assert len(per_operation) == len(operations)
    assert len(sent) >= 2000, len(sent)
    print(f"{len(sent)} generated requests over {len(operations)} operations, no 5xx")


def _fuzz(operation: Any, token: str, sent: list[tuple[str, int]]) -> None:
    """`EXAMPLES_PER_OPERATION` generated requests to one operation."""
    label = f"{operation.method.upper()} {operation.path}"

    @given(case=operation.as_strategy())
    @settings(max_examples=EXAMPLES_PER_OPERATION, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    def call(case: Any) -> None:
        headers = {"Authorization": f"Bearer {token}"} if len(sent) % 2 == 0 else {}
        response = case.call(headers=headers)
        sent.append((label, response.status_code))
        assert response.status_code < 500, (label, response.text[:500])

    call()
