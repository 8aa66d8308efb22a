"""The planner registry: every planner registers here under a versioned id.

Ids look like ``classic-v1``: a name (lower case letters, digits, ``_`` and ``-``, starting with
a letter) and a version. `parse_id` and `format_id` are the one definition of that grammar.
Lookups (`spec`, `make`) ignore case and surrounding white space; asking for ``classic`` gives
its highest registered version. Registration takes the canonical lower-case name only, so a
name is spelt one way wherever it is stored.

Where planners come from, in this order:

- the built-in planners (`planners.builtin`), registered before anything else: the first
  `register` call or the first lookup registers them, whichever comes first;
- third-party packages, through entry points of the group ``flybo.planners``. Each entry point
  names a module, whose import registers its planners, or a callable, called once without
  arguments, that registers them. They are loaded once, at the first lookup; a failing one
  raises `PlannerPluginError` naming it, at that lookup and every later one;
- `register` called directly, at any time.

A registered id is never replaced: stored results name the code they were made with, so a
changed planner is registered under a new version (see `flybo.versions`).
"""

from __future__ import annotations

import difflib
import re
import threading
import types
from collections.abc import Mapping
from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points
from typing import Any

from pydantic import ValidationError

from planners.api import Planner, PlannerConfig
from planners.fidelity import METHODS, ORIGINAL, UNSTATED

ENTRY_POINT_GROUP = "flybo.planners"
BUILTIN = "builtin"
DIRECT = "direct"

_ID = re.compile(r"^(?P<name>[a-z][a-z0-9_-]*?)(?:-v(?P<version>\d+))?$")


class UnknownPlannerError(ValueError):
    """No planner is registered under the requested name."""

    def __init__(self, message: str, *, suggestions: list[str], known: list[str]) -> None:
        super().__init__(message)
        self.suggestions = suggestions
        self.known = known


class PlannerConfigError(ValueError):
    """The configuration given for a planner is invalid."""


class PlannerPluginError(RuntimeError):
    """An entry point of the group ``flybo.planners`` failed to load."""


@dataclass(frozen=True)
class PlannerSpec:
    """One registered planner version.

    `origin` is ``"builtin"``, ``"entry point <name> = <value>"`` or ``"direct"`` (a `register`
    call outside both). `method` is one of `METHODS`: whether this version is the method of
    `reference` as published (``"original"``), differs from it (``"variant"``), or does not say.
    """

    name: str
    version: int
    cls: type[Planner]
    description: str
    reference: str
    origin: str = DIRECT
    method: str = UNSTATED

    @property
    def id(self) -> str:
        return format_id(self.name, self.version)

    @property
    def builtin(self) -> bool:
        return self.origin == BUILTIN

    @property
    def config_model(self) -> type[PlannerConfig]:
        return self.cls.config_model


def format_id(name: str, version: int) -> str:
    """The id of version `version` of planner `name`: ``name-vN``."""
    return f"{name}-v{version}"


def parse_id(text: str) -> tuple[str, int | None]:
    """(name, version) of ``name-vN``, or (name, None) of a bare name; case and surrounding
    white space are ignored.

    Raises:
        ValueError: when `text` is no planner id.
    """
    match = _ID.match(_normalise(text))
    if match is None:
        raise ValueError(f"malformed planner id {text!r}: expected name-vN, e.g. classic-v1")
    version = match.group("version")
    return match.group("name"), None if version is None else int(version)


def _normalise(text: str) -> str:
    return text.strip().lower()


_REGISTRY: dict[str, dict[int, PlannerSpec]] = {}
# Reentrant: loading the built-ins or a plugin calls `register`, and a plugin may look up others.
_LOCK = threading.RLock()
_origin = DIRECT  # the origin given to registrations, set while built-ins or a plugin load
_builtins_loaded = False
_plugins_loaded = False
_plugins_loading = False
_plugin_error: PlannerPluginError | None = None


def register(
    name: str, version: int, cls: type[Planner], *, description: str, reference: str = "",
    method: str = UNSTATED,
) -> PlannerSpec:
    """Register `cls` as `name-v{version}`; registering the same id twice is an error.
    `method`: ``"original"`` if it is the method of `reference` as published, ``"variant"``
    if it differs from it, ``""`` to leave it unstated."""
    if isinstance(version, bool) or not isinstance(version, int) or version < 0:
        raise ValueError(f"invalid version {version!r} for planner {name!r}: an integer >= 0")
    match = _ID.match(name) if isinstance(name, str) else None
    if match is None or match.group("version") is not None:
        hint = ""
        if isinstance(name, str) and _ID.match(_normalise(name)) and _normalise(name) != name:
            hint = f" (did you mean {_normalise(name)!r}?)"
        raise ValueError(
            f"invalid planner name {name!r}: lower case letters, digits, '_' and '-', starting "
            f"with a letter, without a version suffix{hint}"
        )
    if not (isinstance(cls, type) and issubclass(cls, Planner)):
        raise TypeError(f"planner {format_id(name, version)}: {cls!r} is not a Planner subclass")
    if method not in METHODS:
        raise ValueError(f"planner {format_id(name, version)}: method {method!r} is none of "
                         f"'original', 'variant' or '' (not stated)")
    with _LOCK:
        _ensure_builtins()
        existing = _REGISTRY.get(name, {}).get(version)
        if existing is not None:
            raise ValueError(
                f"planner {existing.id} is already registered ({existing.origin}); "
                "a changed planner needs a new version"
            )
        spec_ = PlannerSpec(name, version, cls, description, reference, _origin, method)
        _REGISTRY.setdefault(name, {})[version] = spec_
        return spec_


def _snapshot() -> dict[str, dict[int, PlannerSpec]]:
    return {name: dict(versions) for name, versions in _REGISTRY.items()}


def _restore(snapshot: dict[str, dict[int, PlannerSpec]]) -> None:
    _REGISTRY.clear()
    _REGISTRY.update(snapshot)


def _ensure_builtins() -> None:
    """Register the built-in planners once, before any other; all of them or none."""
    global _builtins_loaded, _origin
    with _LOCK:
        if _builtins_loaded or _origin == BUILTIN:
            return
        # Imported at the first lookup, not with this module: the built-ins import every planner
        # and its numerical libraries, which a plugin registering itself does not need.
        from planners.builtin import BUILTINS

        before, previous = _snapshot(), _origin
        _origin = BUILTIN
        try:
            for name, version, cls, method, description, reference in BUILTINS:
                register(name, version, cls, description=description, reference=reference,
                         method=method)
        except BaseException:
            _restore(before)
            raise
        finally:
            _origin = previous
        _builtins_loaded = True


def _entry_point_label(ep: EntryPoint) -> str:
    dist = getattr(ep, "dist", None)
    where = f" (distribution {dist.name} {dist.version})" if dist is not None else ""
    return f"{ep.name} = {ep.value}{where}"


def _load_entry_point(ep: EntryPoint) -> None:
    global _origin
    before, previous = _snapshot(), _origin
    _origin = f"entry point {ep.name} = {ep.value}"
    try:
        target = ep.load()
        if isinstance(target, types.ModuleType):
            pass  # importing the module registered its planners
        elif callable(target):
            target()
        else:
            raise TypeError(f"it names a {type(target).__name__}, neither a module nor a callable")
    except Exception as exc:
        _restore(before)  # none of its planners, rather than some
        raise PlannerPluginError(
            f"loading planner entry point {_entry_point_label(ep)!r} of group "
            f"{ENTRY_POINT_GROUP!r} failed: {type(exc).__name__}: {exc}"
        ) from exc
    finally:
        _origin = previous


def _ensure_loaded() -> None:
    """The built-ins, then every entry point of the group, each loaded once."""
    global _plugins_loaded, _plugins_loading, _plugin_error
    with _LOCK:
        _ensure_builtins()
        if _plugins_loading:
            return  # a plugin looking up planners while it loads
        if not _plugins_loaded:
            _plugins_loading = True
            errors: list[PlannerPluginError] = []
            try:
                found = entry_points(group=ENTRY_POINT_GROUP)
                for ep in sorted(found, key=lambda e: (e.name, e.value)):
                    try:
                        _load_entry_point(ep)
                    except PlannerPluginError as exc:
                        errors.append(exc)
            finally:
                _plugins_loading = False
                _plugins_loaded = True
            if len(errors) == 1:
                _plugin_error = errors[0]
            elif errors:
                _plugin_error = PlannerPluginError("; ".join(str(e) for e in errors))
                _plugin_error.__cause__ = errors[0]
        if _plugin_error is not None:
            raise _plugin_error


def planner_ids() -> list[str]:
    """Every registered id, sorted."""
    _ensure_loaded()
    return _ids()


def _ids() -> list[str]:
    return sorted(spec_.id for versions in _REGISTRY.values() for spec_ in versions.values())


def default_version(versions: Mapping[int, PlannerSpec]) -> PlannerSpec:
    """The version a bare name stands for: its newest original version (the method as
    published), or its newest version when none is marked original."""
    original = [v for v, s in versions.items() if s.method == ORIGINAL]
    return versions[max(original) if original else max(versions)]


def planner_names() -> list[str]:
    """Every registered name, sorted (each stands for its `default_version`)."""
    _ensure_loaded()
    return sorted(name for name, versions in _REGISTRY.items() if versions)


def specs() -> list[PlannerSpec]:
    """Every registered spec, sorted by id."""
    _ensure_loaded()
    return sorted((s for versions in _REGISTRY.values() for s in versions.values()),
                  key=lambda s: (s.name, s.version))


def _unknown(text: str, message: str, candidates: list[str]) -> UnknownPlannerError:
    key = _normalise(text)
    suggestions = list(dict.fromkeys(difflib.get_close_matches(key, candidates, n=3, cutoff=0.6)))
    known = _ids()
    hint = f" Did you mean {' or '.join(repr(s) for s in suggestions)}?" if suggestions else ""
    return UnknownPlannerError(
        f"{message}.{hint} Known planners: {', '.join(known) or 'none'}.",
        suggestions=suggestions, known=known,
    )


def spec(planner_id: str) -> PlannerSpec:
    """The spec for ``name`` (its `default_version`: the newest original version, else the
    newest) or ``name-vN``; case and surrounding white space are ignored.

    Raises:
        UnknownPlannerError: naming the closest registered ids.
    """
    _ensure_loaded()
    try:
        name, version = parse_id(planner_id)
    except ValueError:
        raise _unknown(planner_id, f"unknown planner {planner_id!r}", _ids()) from None
    versions = _REGISTRY.get(name)
    if not versions:
        candidates = _ids() + sorted(n for n, v in _REGISTRY.items() if v)
        raise _unknown(planner_id, f"unknown planner {planner_id!r}", candidates)
    if version is None:
        return default_version(versions)
    if version not in versions:
        ids = [versions[v].id for v in sorted(versions)]
        raise _unknown(
            planner_id,
            f"unknown version of planner {name!r}: v{version} (known: {', '.join(ids)})",
            ids,
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
