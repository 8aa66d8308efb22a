"""Celery tasks. A task takes a run id only; `worker.runner` makes running it idempotent."""

from __future__ import annotations

from typing import Any

from celery.signals import worker_process_init

from server.queue import RUN_TASK
from server.settings import load_settings
from worker.celery_app import app
from worker.runner import execute_run
from worker.sandbox.isolation import probe_in_background
from worker.speed import measure_speed_in_background


@app.task(name=RUN_TASK, acks_late=True, reject_on_worker_lost=True, ignore_result=True)
def run_episode_task(run_id: int) -> str:
    """Run, measure and store run `run_id`; returns what happened (for the worker's log)."""
    return execute_run(run_id, load_settings())


@worker_process_init.connect
def _measure_machine_speed(**_: Any) -> None:
    """Each pool process (`flybo worker` runs the prefork pool) measures the machine's speed
    factor as it starts, in a thread: the pool's start-up is not held up (Celery kills a
    process that takes seconds to come up), and the runs find it measured. A pool that sends
    no such signal (solo) measures it on its first run, once. The sandbox is probed the same
    way, which also sweeps planner cgroups that killed workers left behind."""
    measure_speed_in_background()
    probe_in_background()
