"""Wall time an episode spends per stage, for the performance figures (never for scoring)."""

from __future__ import annotations

from dataclasses import dataclass

STAGES = ("render", "occupancy", "tsdf", "physics", "planner", "metrics", "recording", "checks")


@dataclass
class StageCosts:
    """Accumulated wall time per stage, seconds; `frames` counts the fused camera frames."""

    render: float = 0.0
    occupancy: float = 0.0
    tsdf: float = 0.0
    physics: float = 0.0
    planner: float = 0.0
    metrics: float = 0.0
    recording: float = 0.0
    checks: float = 0.0  # the in-flight check of the rest of the path (safety stops)
    frames: int = 0

    def per_frame_ms(self) -> dict[str, float]:
        n = max(self.frames, 1)
        return {k: 1000.0 * getattr(self, k) / n for k in STAGES}
