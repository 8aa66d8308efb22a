"""The planner registry: every planner registers here under a versioned name.

Names look like ``classic-v1``; asking for ``classic`` gives the highest registered version.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from pydantic import ValidationError

from planners.api import Planner, PlannerConfig

_ID = re.compile(r"^(?P<name>[a-z][a-z0-9_-]*?)(?:-v(?P<version>\d+))?$")


class UnknownPlannerError(ValueError):
    """No planner is registered under the requested name."""


class PlannerConfigError(ValueError):
    """The configuration given for a planner is invalid."""


@dataclass(frozen=True)
class PlannerSpec:
    """One registered planner version."""

    name: str
    version: int
    cls: type[Planner]
    description: str
    reference: str

    @property
    def id(self) -> str:
        return f"{self.name}-v{self.version}"

    @property
    def config_model(self) -> type[PlannerConfig]:
        return self.cls.config_model


_REGISTRY: dict[str, dict[int, PlannerSpec]] = {}


def register(
    name: str, version: int, cls: type[Planner], *, description: str, reference: str = ""
) -> PlannerSpec:
    """Register `cls` as `name-v{version}`; registering the same id twice is an error."""
    if isinstance(version, bool) or not isinstance(version, int) or version < 0:
        raise ValueError(f"invalid version {version!r} for planner {name!r}: an integer >= 0")
    match = _ID.match(name)
    if match is None or match.group("version") is not None:
        raise ValueError(f"invalid planner name {name!r}: lower case, no version suffix")
    versions = _REGISTRY.setdefault(name, {})
    if version in versions:
        raise ValueError(f"planner {name}-v{version} is already registered")
    spec = PlannerSpec(name, version, cls, description, reference)
    versions[version] = spec
    return spec


def _ensure_builtins() -> None:
    # Imported lazily so that the registry module has no import cycle with the planners.
    import planners.builtin  # noqa: F401


def planner_ids() -> list[str]:
    """Every registered id, sorted."""
    _ensure_builtins()
    return sorted(spec.id for versions in _REGISTRY.values() for spec in versions.values())


def planner_names() -> list[str]:
    """Every registered name (latest versions), sorted."""
    _ensure_builtins()
    return sorted(_REGISTRY)


def spec(planner_id: str) -> PlannerSpec:
    """The spec for ``name`` (latest version) or ``name-vN``."""
    _ensure_builtins()
    match = _ID.match(planner_id.strip().lower())
    versions = _REGISTRY.get(match.group("name"), {}) if match else {}
    if not versions or match is None:
        known = ", ".join(planner_ids()) or "none"
        raise UnknownPlannerError(f"unknown planner {planner_id!r}; known planners: {known}")
    if match.group("version") is None:
        return versions[max(versions)]
    version = int(match.group("version"))
    if version not in versions:
        known = ", ".join(s.id for s in versions.values())
        raise UnknownPlannerError(
            f"unknown version of planner {match.group('name')!r}: v{version}; known: {known}"
        )
    return versions[version]


def make(planner_id: str, config: Mapping[str, Any] | None = None) -> Planner:
    """A new planner instance with `config` validated against its config model."""
    s = spec(planner_id)
    try:
        cfg = s.config_model.model_validate(dict(config or {}))
    except ValidationError as exc:
        problems = "; ".join(
            f"{'.'.join(str(part) for part in err['loc']) or 'config'}: {err['msg']}"
            for err in exc.errors()
        )
        raise PlannerConfigError(f"invalid config for planner {s.id}: {problems}") from exc
    return s.cls(cfg)
