"""The settings of ESM's two variants, with their sources (`planners.esm`)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from planners.api import PlannerConfig


class EsmConfig(PlannerConfig):
    """ESM's settings. Unless noted, defaults are those of the authors' public exploration
    configuration (`exploration_planner.yaml` of mav_active_3d_planning: `trajectory_generator/
    ...` keys, an RRTStar generator)."""

    # Which gain scores a view: ESM-IPP's volumetric or ESM-Recon's reconstruction gain.
    gain: Literal["volumetric", "reconstruction"] = "volumetric"
    # max_extension_range: 1.5
    extension_m: float = Field(1.5, gt=0.0)
    # max_rewire_range: 1.6
    rewire_radius_m: float = Field(1.6, gt=0.0)
    # n_neighbors: 20
    neighbours: int = Field(20, ge=1)
    # max_density_range: 1.0
    density_radius_m: float = Field(1.0, ge=0.0)
    # sampling_mode "semilocal": semilocal_sampling_count: 10
    local_count: int = Field(10, ge=0)
    # semilocal_sampling_radius_max / _min: 1.5
    local_radius_m: float = Field(1.5, gt=0.0)
    # crop_segments: true, crop_margin: 0.3: a segment blocked before its end is cut short
    # of the block by this much ...
    crop_margin_m: float = Field(0.3, ge=0.0)
    # ... and kept if at least this long (crop_min_length: 0.5)
    crop_min_m: float = Field(0.5, gt=0.0)
    # Where samples beyond the semilocal ones are drawn: "box", uniformly in the area (the
    # paper's), or "traversable", uniformly among the map's traversable voxels. Box samples in
    # unknown space pull the tree toward the known boundary; traversable ones fill known space.
    # With the other fixes both covered MAZE (ESM-Recon: traversable in 24 runs, box in 16, all
    # >= 0.98); on WAREHOUSE box did better (ESM-IPP seeds 0, 1: 0.925, 0.903 against 0.916,
    # 0.855), so the paper's stays the default.
    global_sampling: Literal["box", "traversable"] = "box"
    # Our choice: a sample is steered from up to this many nearest nodes, nearest first, until
    # one gives a segment (the paper: the nearest only). In a corridor that bends away from the
    # nearest node, the nearest node's way is blocked and the next one's is clear.
    steer_candidates: int = Field(4, ge=1)
    # Our choice: the paper expands while flying; here each call samples this many points ...
    tries_per_call: int = Field(300, ge=1)
    # ... and stops after this many new segments, to bound the time charged per call.
    new_per_call: int = Field(20, ge=1)
    # sensor_model/ray_length: 5.0 (the camera's range)
    gain_range_m: float | None = Field(5.0, gt=0.0)
    # Our choice: 10° rays, as AEP here; the paper's ContinuousYawPlanningEvaluator tries 12
    # yaws (30° apart), we take the best of the 36 column windows.
    ray_step_deg: float = Field(10.0, gt=0.0, le=30.0)
    # Value (gain per second of flight, m³/s) a branch must exceed to be flown; the paper flies
    # any positive value (min_new_value: 0). Our choice: a trace above 0, so that the last
    # unobservable specks of unknown space do not keep the vehicle roaming.
    min_value: float = Field(0.01, ge=0.0)
    # back_tracker/stack_size: 10 in the paper; our choice: unbounded, so that the vehicle can
    # retrace its whole way before giving up (the tree keeps growing on the way).
    backtrack_stack: int | None = Field(None, ge=1)
    # Our choice: a vehicle within this of the flown segment's end has reached it.
    reach_tolerance_m: float = Field(0.3, gt=0.0)
    # Reconstruction gain (ESM-Recon): unknown volume counts as in the volumetric gain (our
    # choice: the paper counts frontier voxels only, with weight frontier_voxel_weight: 1.0).
    unknown_weight: float = Field(1.0, ge=0.0)
    # The paper counts each visible surface voxel by its TSDF impact, weight 1.
    surface_weight: float = Field(1.0, ge=0.0)
    # Our choice: a surface voxel seen from a new 45° azimuth sector adds half a voxel.
    direction_bonus: float = Field(0.5, ge=0.0)
    # TSDF weight one more frame adds: 1 (one fused frame, the unit of `surface_weight`).
    new_weight: float = Field(1.0, gt=0.0)
    # Our choice: 0.2, i.e. a surface stops counting once fused from 5 frames. The paper's
    # min_impact_factor (0.01) applies to its per-ray TSDF weights; with one unit per fused
    # frame 0.01 keeps a surface worth seeing for 99 frames, and on MAZE the vehicle then kept
    # re-viewing explored walls instead of exploring (coverage 0.616 at 700 s on one seed).
    min_impact: float = Field(0.2, ge=0.0, le=1.0)
    # Our choice: a surface voxel seen from two 45° sectors earns no more direction bonus.
    min_directions: int = Field(2, ge=1, le=8)
    # Gaps up to this wide, m, between occupied voxels along an axis are closed for the gain's
    # rays (None: rays pass them, as in the paper). Our choice, as NBVP's here: on MAZE a traced
    # ESM-Recon run (seed 2, 0.514 at 700 s) spent 400 s following branches worth 0.01-0.3
    # m³/s, left over from wall interiors seen through holes in their occupied layer.
    surface_gap_m: float | None = Field(0.3, gt=0.0)


class EsmReconConfig(EsmConfig):
    """ESM-Recon: the same planner scoring views by their reconstruction gain."""

    gain: Literal["volumetric", "reconstruction"] = "reconstruction"
