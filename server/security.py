"""API tokens: random, shown once, stored only as an HMAC-SHA256 keyed by the secret key.

Tokens carry 256 random bits, so a keyed fast hash is enough: there is nothing to brute-force
that a slow password hash would protect (see `docs/service.md`).
"""

from __future__ import annotations

import hashlib
import hmac
import secrets

from sqlalchemy import select
from sqlalchemy.orm import Session

from server.models import ApiToken, User

TOKEN_PREFIX = "flybo_"
# The owner of the published baselines' runs (`server.baselines`): no one gets its tokens, so
# no one submits as the reference.
REFERENCE_USER = "flybo-reference"
RESERVED_USER_NAMES = frozenset({REFERENCE_USER})


class ReservedUserError(ValueError):
    """Raised for a token asked for a user name the service keeps for itself."""


def hash_token(token: str, secret_key: str) -> str:
    return hmac.new(secret_key.encode(), token.encode(), hashlib.sha256).hexdigest()


def create_token(session: Session, user_name: str, secret_key: str, *,
                 admin: bool = False) -> str:
    """A new token for `user_name` (the user is created if new; `admin` promotes it).

    Raises:
        ReservedUserError: for a name in `RESERVED_USER_NAMES`.
    """
    if user_name.strip().lower() in RESERVED_USER_NAMES:
        raise ReservedUserError(f"the user name {user_name!r} is reserved for the service's "
                                "published baselines; choose another")
    user = session.scalar(select(User).where(User.name == user_name))
    if user is None:
        user = User(name=user_name, is_admin=admin)
        session.add(user)
        session.flush()
    elif admin:
        user.is_admin = True
    token = TOKEN_PREFIX + secrets.token_urlsafe(32)
    session.add(ApiToken(user_id=user.id, token_hash=hash_token(token, secret_key),
                         prefix=token[: len(TOKEN_PREFIX) + 4]))
    return token


def user_for_token(session: Session, token: str, secret_key: str) -> User | None:
    row = session.scalar(
        select(ApiToken).where(ApiToken.token_hash == hash_token(token, secret_key),
                               ApiToken.revoked.is_(False))
    )
    return None if row is None else row.user
