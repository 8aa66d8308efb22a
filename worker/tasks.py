"""Celery tasks. A task takes a run id only; `worker.runner` makes running it idempotent."""

from __future__ import annotations

from server.queue import RUN_TASK
from server.settings import load_settings
from worker.celery_app import app
from worker.runner import execute_run


@app.task(name=RUN_TASK, acks_late=True, reject_on_worker_lost=True, ignore_result=True)
def run_episode_task(run_id: int) -> str:
    """Run, measure and store run `run_id`; returns what happened (for the worker's log)."""
    return execute_run(run_id, load_settings())
