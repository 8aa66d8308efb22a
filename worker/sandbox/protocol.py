"""The messages between the episode runner and a sandboxed planner: JSON lines, never pickle.

Runner to planner: ``{"op": "reset", "ctx": ...}``, ``{"op": "plan", "obs": ..., "box": ...}``.
Planner to runner: ``{"ok": true, ...}`` or ``{"ok": false, "error": "..."}``.
Everything the planner sends is untrusted: `decode_plan` checks every field and type.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
from typing import IO, Any

import numpy as np
from pydantic import BaseModel

from sim.camera import CameraConfig
from sim.geometry import Pose
from sim.interface import Observation, Plan, PlannerContext, PlanOutcome
from sim.occupancy import IndexBox
from sim.vehicle import VehicleLimits

MAX_MESSAGE_BYTES = 8 * 1024 * 1024
MAX_WAYPOINTS = 10_000
MAX_INFO_ITEMS = 64


class ProtocolError(ValueError):
    """A message that breaks the protocol: too long, not JSON, or wrong fields and types."""


def to_jsonable(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Pose):
        return {"position": value.position.tolist(), "yaw": float(value.yaw)}
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, BaseModel):
        return value.model_dump(mode="json")
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [to_jsonable(v) for v in value]
    return value


def encode_message(message: dict[str, Any]) -> bytes:
    """One JSON line; `ProtocolError` when it would exceed `MAX_MESSAGE_BYTES`."""
    data = json.dumps(message, allow_nan=False, separators=(",", ":")).encode() + b"\n"
    if len(data) > MAX_MESSAGE_BYTES:
        raise ProtocolError(f"message of {len(data)} bytes exceeds {MAX_MESSAGE_BYTES}")
    return data


def write_message(stream: IO[bytes], message: dict[str, Any]) -> None:
    stream.write(encode_message(message))
    stream.flush()


def parse_message(line: bytes) -> dict[str, Any]:
    if len(line) > MAX_MESSAGE_BYTES or not line.endswith(b"\n"):
        raise ProtocolError("message too long or cut off")
    try:
        message = json.loads(line)
    except (ValueError, RecursionError) as exc:
        raise ProtocolError(f"not JSON: {exc}") from None
    if not isinstance(message, dict):
        raise ProtocolError("a message must be a JSON object")
    return message


# -- context and observation: runner to planner (trusted) ---------------------------------------

def encode_context(ctx: PlannerContext) -> dict[str, Any]:
    out = {f.name: to_jsonable(getattr(ctx, f.name)) for f in dataclasses.fields(ctx)
           if f.name != "rng"}
    out["rng_state"] = ctx.rng.bit_generator.state
    out["rng_kind"] = type(ctx.rng.bit_generator).__name__
    return out


def decode_context(data: dict[str, Any]) -> PlannerContext:
    bit_generator = getattr(np.random, data["rng_kind"])()
    bit_generator.state = data["rng_state"]
    values: dict[str, Any] = {}
    for f in dataclasses.fields(PlannerContext):
        if f.name == "rng":
            values[f.name] = np.random.Generator(bit_generator)
        elif f.name in ("bounds_min", "bounds_max"):
            values[f.name] = np.asarray(data[f.name], dtype=np.float64)
        elif f.name == "start":
            values[f.name] = _pose(data[f.name])
        elif f.name == "limits":
            values[f.name] = VehicleLimits(**data[f.name])
        elif f.name == "camera":
            values[f.name] = CameraConfig(**data[f.name])
        else:
            values[f.name] = data[f.name]
    return PlannerContext(**values)


def _pose(data: dict[str, Any]) -> Pose:
    return Pose(np.asarray(data["position"], dtype=np.float64), float(data["yaw"]))


def encode_observation(obs: Observation) -> dict[str, Any]:
    return {f.name: to_jsonable(getattr(obs, f.name)) for f in dataclasses.fields(obs)
            if f.name != "map"}


def decode_observation(data: dict[str, Any], map_view: Any) -> Observation:
    values: dict[str, Any] = {}
    for f in dataclasses.fields(Observation):
        if f.name == "map":
            values[f.name] = map_view
        elif f.name == "pose":
            values[f.name] = _pose(data[f.name])
        elif f.name == "last_outcome":
            values[f.name] = PlanOutcome(data[f.name])
        elif isinstance(data.get(f.name), list):
            values[f.name] = np.asarray(data[f.name], dtype=np.float64)
        else:
            values[f.name] = data[f.name]
    return Observation(**values)


# -- plans: planner to runner (untrusted) -------------------------------------------------------

def encode_plan(plan: Plan) -> dict[str, Any]:
    if not isinstance(plan, Plan):
        raise ProtocolError(f"plan() must return a Plan, not {type(plan).__name__}")
    try:
        finite = bool(np.all(np.isfinite(np.asarray(plan.waypoints, dtype=np.float64))))
    except (TypeError, ValueError):
        raise ProtocolError("the plan's waypoints are not an array of numbers") from None
    if not finite:
        raise ProtocolError("the plan's waypoints are not finite (NaN or infinity)")
    return {f.name: to_jsonable(getattr(plan, f.name)) for f in dataclasses.fields(plan)}


def _number(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ProtocolError(f"{what} must be a number")
    return float(value)


def decode_plan(data: Any) -> Plan:
    """A `Plan` from untrusted JSON; `ProtocolError` names the first thing wrong.

    Finite numbers and the area's bounds are checked later by the framework, as for any planner.
    """
    if not isinstance(data, dict):
        raise ProtocolError("a plan must be a JSON object")
    known = {f.name for f in dataclasses.fields(Plan)}
    unknown = set(data) - known
    if unknown:
        raise ProtocolError(f"unknown plan fields: {', '.join(sorted(unknown))}")
    values: dict[str, Any] = {}
    raw = data.get("waypoints", [])
    if not isinstance(raw, list) or len(raw) > MAX_WAYPOINTS:
        raise ProtocolError(f"waypoints must be a list of at most {MAX_WAYPOINTS} rows")
    rows = []
    for row in raw:
        if not isinstance(row, list) or len(row) != 4:
            raise ProtocolError("each waypoint must be [x, y, z, yaw]")
        rows.append([_number(v, "a waypoint coordinate") for v in row])
    values["waypoints"] = np.asarray(rows, dtype=np.float64).reshape(-1, 4)
    for f in dataclasses.fields(Plan):
        if f.name in ("waypoints", "info") or f.name not in data:
            continue
        value = data[f.name]
        if isinstance(f.default, bool):  # flags such as `done`
            if not isinstance(value, bool):
                raise ProtocolError(f"{f.name} must be true or false")
            values[f.name] = value
        elif value is not None:
            values[f.name] = _number(value, f.name)
    info = data.get("info", {})
    if not isinstance(info, dict) or len(info) > MAX_INFO_ITEMS:
        raise ProtocolError(f"info must be an object of at most {MAX_INFO_ITEMS} items")
    clean: dict[str, Any] = {}
    for key, value in info.items():
        if isinstance(value, str):
            clean[str(key)[:64]] = value[:256]
        elif isinstance(value, int | float) and not isinstance(value, bool):
            clean[str(key)[:64]] = value if math.isfinite(value) else None
    values["info"] = clean
    return Plan(**values)


# What the planner process reports of a call, ms: refreshing its map and the planner's `plan`.
TIMING_KEYS = ("map", "plan")


def clean_timing(timing: Any) -> dict[str, float]:
    """The known keys of a reply's untrusted `timing_ms`, finite non-negative numbers only."""
    if not isinstance(timing, dict):
        return {}
    clean = {}
    for key in TIMING_KEYS:
        value = timing.get(key)
        if (isinstance(value, int | float) and not isinstance(value, bool)
                and math.isfinite(value) and value >= 0):
            clean[key] = float(value)
    return clean


def box_message(box: IndexBox | None) -> list[list[int]] | None:
    """A box of changed voxels as sent: its lower and upper corners, or None."""
    return None if box is None else [list(box.lo), list(box.hi)]


# The area's name as the planner process is told it: the name would let a planner that knows
# the built-in areas rebuild the exact scene, ground truth included.
HIDDEN_AREA = "hidden"


def hide_area(ctx: PlannerContext) -> PlannerContext:
    """`ctx` without the area's name, for the planner process."""
    return dataclasses.replace(ctx, area=HIDDEN_AREA)
