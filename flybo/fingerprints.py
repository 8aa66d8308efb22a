"""The hashes that name the benchmark's code: one SHA-256 per component (``sim``, ``presets``,
``areas``, ``libraries``) and a fingerprint per planner; `flybo.versions` describes what each
covers and holds them to the lock file."""

from __future__ import annotations

import dataclasses
import enum
import functools
import hashlib
import importlib.metadata
import json
from collections.abc import Callable
from typing import Any

from flybo.cpu_kernels import (
    CORETYPE_ENV,
    NUMPY_FEATURES_ENV,
    PINNED_CORETYPE,
    PINNED_NUMPY_DISABLED,
)
from flybo.module_sources import closure, package_sources, sorted_sources

COMPONENTS = ("sim", "presets", "areas", "libraries")
# The installed libraries whose numbers shape a flight (ray casting, integration, physics,
# trajectories, planners' numerics): the same code flies differently with another release of
# one of them, so their versions are part of the benchmark version (pinned in pyproject.toml).
FLIGHT_LIBRARIES = ("numpy", "numba", "open3d", "pybullet", "ruckig", "scipy")
# Planner dependencies outside these are not followed (see `flybo.versions`).
_PLANNER_PACKAGES = ("planners",)
_PLANNER_EXTRA_MODULES = ("sim.interface",)
_NOT_FOLLOWED = ("planners.registry", "planners.builtin")


def canonical_json(value: Any) -> str:
    """`value` as JSON with sorted keys and no white space: the same value, the same text."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=False,
                      allow_nan=False)


def sha256_of(value: Any) -> str:
    """SHA-256 (hex) of the canonical JSON of `value`."""
    return hashlib.sha256(canonical_json(value).encode("utf-8")).hexdigest()


# -- components -----------------------------------------------------------------------------------


def _to_json(value: Any) -> Any:
    """A JSON-able description of a parameter value (dataclasses, tuples, enums, numpy)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {"__type__": f"{type(value).__module__}.{type(value).__qualname__}",
                **{f.name: _to_json(getattr(value, f.name)) for f in dataclasses.fields(value)}}
    if isinstance(value, enum.Enum):
        return _to_json(value.value)
    if isinstance(value, dict):
        return {str(k): _to_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_to_json(v) for v in value]
    if hasattr(value, "tolist"):  # numpy arrays and scalars
        return _to_json(value.tolist())
    if isinstance(value, float) and value != value:
        return "nan"
    if isinstance(value, float) and value in (float("inf"), float("-inf")):
        return str(value)
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if callable(value):
        return _describe_callable(value)
    raise TypeError(f"cannot describe {type(value).__name__} {value!r} for a version hash")


def _describe_callable(fn: Any) -> Any:
    if isinstance(fn, functools.partial):
        return {"function": _describe_callable(fn.func), "args": _to_json(list(fn.args)),
                "kwargs": _to_json(dict(fn.keywords))}
    return f"{fn.__module__}.{fn.__qualname__}"


def _sim_hash() -> str:
    return sha256_of(package_sources("sim"))


def _presets_hash() -> str:
    from sim.config import PRESETS

    return sha256_of({name: cfg.model_dump(mode="json") for name, cfg in PRESETS.items()})


def _areas_hash() -> str:
    import areas.registry as area_registry

    modules = closure(["areas.registry", "areas.ground_truth"],
                      lambda m: m == "areas" or m.startswith("areas."))
    generators = getattr(area_registry, "_GENERATORS", {})
    builders = getattr(area_registry, "_builders", {})
    scenes = {name: {"generator": _describe_callable(generators[name]),
                     "builder": _describe_callable(builders[name]) if name in builders else None}
              for name in sorted(generators)}
    return sha256_of({"sources": sorted_sources(modules), "areas": scenes})


def library_versions() -> dict[str, str]:
    """{distribution: installed version} of each of `FLIGHT_LIBRARIES`."""
    return {name: importlib.metadata.version(name) for name in FLIGHT_LIBRARIES}


def _libraries_hash() -> str:
    # With the CPU kernels they run on: another choice sums and rounds differently.
    kernels = {CORETYPE_ENV: PINNED_CORETYPE, NUMPY_FEATURES_ENV: PINNED_NUMPY_DISABLED}
    return sha256_of({**library_versions(), "cpu_kernels": kernels})


_COMPONENT_HASHES: dict[str, Callable[[], str]] = {
    "sim": _sim_hash, "presets": _presets_hash, "areas": _areas_hash,
    "libraries": _libraries_hash,
}


def component_hashes() -> dict[str, str]:
    """SHA-256 of each component of the benchmark in this tree: ``sim``, ``presets``, ``areas``
    and the installed ``libraries``."""
    return {name: _COMPONENT_HASHES[name]() for name in COMPONENTS}


# -- planners -------------------------------------------------------------------------------------


def planner_modules(cls: type) -> dict[str, tuple[str, str]]:
    """{module: (relative path, source)} of the modules planner class `cls` depends on."""
    own_top = cls.__module__.partition(".")[0]
    packages = {*_PLANNER_PACKAGES, own_top}

    def follow(module: str) -> bool:
        if module in _NOT_FOLLOWED:
            return False
        if module in _PLANNER_EXTRA_MODULES:
            return True
        return module.partition(".")[0] in packages

    config_model = getattr(cls, "config_model", None)
    classes = [*cls.__mro__, *(config_model.__mro__ if isinstance(config_model, type) else ())]
    roots = dict.fromkeys(c.__module__ for c in classes)
    return closure(roots, follow)


def fingerprint_of_class(cls: type) -> str:
    """The fingerprint of planner class `cls` with its default configuration."""
    config = cls.config_model().model_dump(mode="json")  # type: ignore[attr-defined]
    return sha256_of({
        "class": f"{cls.__module__}.{cls.__qualname__}",
        "config": config,
        "sources": sorted_sources(planner_modules(cls)),
    })


def planner_fingerprint(planner_id: str) -> str:
    """The fingerprint of registered planner `planner_id` (``name`` means its default version).
    """
    from planners.registry import spec

    return fingerprint_of_class(spec(planner_id).cls)


def planner_fingerprints(*, builtin_only: bool = True) -> dict[str, str]:
    """{id: fingerprint} of every registered planner, or of the built-in ones (the lock's)."""
    from planners.registry import specs

    return {s.id: fingerprint_of_class(s.cls) for s in specs() if s.builtin or not builtin_only}
