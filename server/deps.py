"""FastAPI dependencies: settings, a database session per request, the calling user."""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Annotated

from fastapi import Depends, HTTPException, Path, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from sqlalchemy.orm import Session, sessionmaker

from server.models import User, utcnow
from server.security import user_for_token
from server.settings import Settings

bearer = HTTPBearer(auto_error=False, description="an API token from `flybo tokens create`")


async def get_settings(request: Request) -> Settings:
    settings: Settings = request.app.state.settings
    return settings


async def get_session(request: Request) -> AsyncIterator[Session]:
    # An async dependency on purpose: a sync one would need a worker thread to close the
    # session after the response, and with every thread busy waiting for a pooled connection
    # that close could never run (a deadlock under load). Closing only returns a connection.
    # Reads get sessions that never take SQLite's write lock (see server.db).
    reads = request.method in ("GET", "HEAD")
    state = request.app.state
    factory: sessionmaker[Session] = (getattr(state, "read_sessions", state.sessions) if reads
                                      else state.sessions)
    session = factory()
    try:
        yield session
    finally:
        session.close()


SettingsDep = Annotated[Settings, Depends(get_settings)]
SessionDep = Annotated[Session, Depends(get_session)]


def current_user(
    session: SessionDep,
    settings: SettingsDep,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)],
) -> User:
    if credentials is None or credentials.scheme.lower() != "bearer":
        raise HTTPException(401, "an API token is required: send 'Authorization: Bearer TOKEN'",
                            headers={"WWW-Authenticate": "Bearer"})
    user = user_for_token(session, credentials.credentials, settings.secret_key)
    if user is None:
        raise HTTPException(401, "invalid or revoked API token",
                            headers={"WWW-Authenticate": "Bearer"})
    return user


def optional_user(
    session: SessionDep,
    settings: SettingsDep,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)],
) -> User | None:
    if credentials is None:
        return None
    return current_user(session, settings, credentials)


UserDep = Annotated[User, Depends(current_user)]
# Database ids are 32-bit on every backend: a larger number names nothing (404 rather than 500).
IdPath = Annotated[int, Path(ge=1, le=2**31 - 1, description="an id")]
OptionalUserDep = Annotated[User | None, Depends(optional_user)]

__all__ = ["IdPath", "OptionalUserDep", "SessionDep", "SettingsDep", "UserDep", "utcnow"]
