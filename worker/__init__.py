"""Celery app and tasks that run episodes, and the sandbox for uploaded planners."""
