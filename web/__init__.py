"""What a browser sees: leaderboard pages, plots and the 3D replay."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from fastapi import FastAPI


def install_web(app: FastAPI) -> None:
    """Mount the website's routes and static files on the service's app."""
    from web.pages import router

    app.include_router(router)
