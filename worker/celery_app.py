"""The Celery application of the workers (`flybo worker` starts it)."""

from __future__ import annotations

from celery import Celery

from server.queue import make_celery
from server.settings import load_settings


def create_celery() -> Celery:
    app = make_celery(load_settings(), name="flybo-worker")
    app.conf.update(include=["worker.tasks"])
    return app


app = create_celery()
