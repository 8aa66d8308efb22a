"""Who sees what of the held-out split (`server.heldout`): admins see everything; everyone else
sees a held-out area only as its opaque name, and a run on one only as its metrics.

Hidden from them: the area's family, seed, title, statistics and content hash, its mesh and
thumbnail (it is left out of area listings), and a held-out run's files (recording, mesh,
result), log and reproducibility record, which would show or fingerprint the scene.
"""

from __future__ import annotations

from fastapi import HTTPException

from server.models import HELDOUT_SPLIT, AreaRow, User

HIDDEN_SCENE = "held-out area: its scene is shown to admins only"


def sees_heldout(user: User | None) -> bool:
    """Whether `user` may see held-out scenes (admins only; nobody without a token)."""
    return user is not None and user.is_admin


def scene_hidden(area: AreaRow, user: User | None) -> bool:
    """Whether `area`'s scene (name aside) must be hidden from `user`."""
    return area.split == HELDOUT_SPLIT and not sees_heldout(user)


def refuse_hidden(area: AreaRow, user: User | None, status: int = 404) -> None:
    """An HTTP error when `area`'s scene is hidden from `user` (404: as if there were none)."""
    if scene_hidden(area, user):
        raise HTTPException(status, HIDDEN_SCENE)
