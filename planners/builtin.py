"""The built-in planners, registered in one place."""

from __future__ import annotations

from planners.classic import Classic
from planners.registry import register

register(
    "classic",
    1,
    Classic,
    description="Nearest frontier by path length (Yamauchi 1997), replanned at every waypoint.",
    reference="B. Yamauchi, A frontier-based approach for autonomous exploration, CIRA 1997",
)
