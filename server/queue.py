"""The Celery configuration shared by the API (which only enqueues) and the workers.

Tasks take run ids only, are acknowledged late and rejected (requeued) when their worker dies,
and each worker takes one message at a time. The default broker is kombu's filesystem transport
under the data folder: no server to install for the embedded service.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Any

from celery import Celery

from server.settings import Settings

RUN_TASK = "flybo.run_episode"
QUEUE = "flybo-runs"


def celery_config(settings: Settings) -> dict[str, Any]:
    config: dict[str, Any] = {
        "broker_url": settings.broker,
        "task_acks_late": True,
        "task_reject_on_worker_lost": True,
        "worker_prefetch_multiplier": 1,
        "task_ignore_result": True,
        "task_serializer": "json",
        "accept_content": ["json"],
        "task_default_queue": QUEUE,
        "broker_connection_retry_on_startup": True,
        "worker_hijack_root_logger": False,
        "worker_send_task_events": False,
    }
    if settings.broker.startswith("filesystem"):
        folder = settings.broker_folder
        for sub in ("queue", "processed", "control"):
            (folder / sub).mkdir(parents=True, exist_ok=True)
        config["broker_transport_options"] = {
            "data_folder_in": str(folder / "queue"),
            "data_folder_out": str(folder / "queue"),
            "processed_folder": str(folder / "processed"),
            "store_processed": False,
            "control_folder": str(folder / "control"),  # else "./control" in the cwd
        }
    elif settings.broker.startswith(("redis", "rediss")):
        # An unacknowledged message comes back after this long; runs are limited well below it
        # and the sweeper requeues lost runs much sooner.
        longest = settings.run_time_limit_s(settings.max_seconds_per_run)
        config["broker_transport_options"] = {"visibility_timeout": int(longest * 2 + 600)}
    return config


def make_celery(settings: Settings, name: str = "flybo") -> Celery:
    app = Celery(name)
    app.conf.update(celery_config(settings))
    return app


@lru_cache(maxsize=8)
def _producer(broker: str, folder: str) -> Celery:
    return make_celery(Settings(broker_url=broker, data_dir=Path(folder)), name="flybo-producer")


def enqueue_run(settings: Settings, run_id: int, sim_seconds: float) -> None:
    """Put one run on the queue. Call after the transaction that created the run committed.

    The message carries the run's wall-time limits: soft (the task fails the run cleanly) and
    hard (the worker process is killed, and the sweeper fails or requeues the run)."""
    app = _producer(settings.broker, str(settings.resolved_data_dir))
    app.send_task(RUN_TASK, args=[run_id], queue=QUEUE,
                  soft_time_limit=settings.run_soft_time_limit_s(sim_seconds),
                  time_limit=settings.run_time_limit_s(sim_seconds))
