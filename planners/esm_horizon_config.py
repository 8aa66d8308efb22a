"""The settings of `esm-ipp-v2` and `esm-recon-v2` (`planners.esm_horizon`), with their sources.

Two public configurations of ESM stand behind them: the authors' exploration configuration
(`exploration_planner.yaml` of ethz-asl/mav_active_3d_planning, which `planners.esm_config`
follows), and the configurations the FLYBO authors ran ESM with in their benchmark
(abourki/mav_active_3d_planning, `active_3d_planning_app_reconstruction/cfg/planners/esm_cfg/`):
indoors (`office_b.yaml`, `office_c.yaml`, `facility_c.yaml`) the same tree as the exploration
configuration, on WAREHOUSE, PLATFORM A and POWERPLANT (`warehouse.yaml`, `platform_a.yaml`,
`pp.yaml`) a coarser one with twice the segment length, density and update range.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from planners.esm_config import EsmConfig


class EsmLargeArea(BaseModel):
    """The tree ESM grows on a large area: the FLYBO authors' `esm_cfg/warehouse.yaml` and
    `esm_cfg/pp.yaml` (`trajectory_generator/...` and `ContinuousYawPlanningEvaluator` keys)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    # max_extension_range: 3.0 ("3m for powerplant")
    extension_m: float = Field(3.0, gt=0.0)
    # max_rewire_range: 3.1
    rewire_radius_m: float = Field(3.1, gt=0.0)
    # max_density_range: 2.
    density_radius_m: float = Field(2.0, ge=0.0)
    # crop_margin: 2.
    crop_margin_m: float = Field(2.0, ge=0.0)
    # crop_min_length: 2.5
    crop_min_m: float = Field(2.5, gt=0.0)
    # min_path_length: 2.5
    min_segment_m: float = Field(2.5, ge=0.0)
    # semilocal_sampling_count: 15
    local_count: int = Field(15, ge=0)
    # ContinuousYawPlanningEvaluator/update_range: 6.0
    update_range_m: float | None = Field(6.0, gt=0.0)


class EsmHorizonConfig(EsmConfig):
    """`EsmConfig` (the authors' exploration configuration and our documented choices) plus the
    original's local horizon and minimum segment length, and the FLYBO authors' large-area tree.
    """

    # ContinuousYawPlanningEvaluator/update_range: 3.0 in exploration_planner.yaml (and the FLYBO
    # authors' indoor configurations): at each replan only views within this distance of the
    # vehicle are re-evaluated; farther nodes keep the gain they were given (None: every stale
    # gain on the way to the best branch is recomputed, as esm-ipp-v1 does).
    update_range_m: float | None = Field(3.0, gt=0.0)
    # min_path_length: 0.5 in exploration_planner.yaml: no segment (new, or a new connection of
    # the RRT* rewiring) shorter than this (the original's `connectPoses` refuses it).
    min_segment_m: float = Field(0.5, ge=0.0)
    # Areas mapped at this voxel size or coarser fly the large-area tree (`large`); None: never.
    # The benchmark maps WAREHOUSE, PLATFORM B and POWERPLANT at 0.2 m and the others at 0.1 m
    # (the FLYBO paper's resolutions), and the FLYBO authors ran ESM with their large-area
    # configuration on WAREHOUSE, PLATFORM A and POWERPLANT: the voxel size is what a planner
    # can tell of it. PLATFORM A (0.1 m) flies the indoor tree (docs/planners/esm.md); v3
    # (`EsmHorizonV3Config`) also reads the area's indoor / outdoor class.
    large_area_voxel_m: float | None = Field(0.2, gt=0.0)
    large: EsmLargeArea = EsmLargeArea()
    # Which settings apply: "auto" by `large_tree_auto`, or one of the two everywhere.
    profile: Literal["auto", "indoor", "large"] = "auto"

    def for_area(self, voxel_size: float, indoor: bool) -> EsmHorizonConfig:
        """The settings that apply on a map of `voxel_size` of an area of that class: the
        large-area tree's in place of the others where `profile` (or, for "auto",
        `large_tree_auto`) says so."""
        large = self.profile == "large" or (
            self.profile == "auto" and self.large_tree_auto(voxel_size, indoor))
        if not large:
            return self
        return self.model_copy(update=self.large.model_dump())

    def large_tree_auto(self, voxel_size: float, indoor: bool) -> bool:
        """Whether "auto" grows the large-area tree: by the voxel size alone."""
        return (self.large_area_voxel_m is not None
                and voxel_size >= self.large_area_voxel_m - 1e-9)


class EsmHorizonV3Config(EsmHorizonConfig):
    """`EsmHorizonConfig`, and the large-area tree on every outdoor area."""

    # The FLYBO authors ran their large-area configuration on PLATFORM A too (`platform_a.yaml`:
    # the tree of `warehouse.yaml`, crops 1.5 / 1.8 m), an outdoor area mapped at 0.1 m. With
    # the area's class in the planner's context, "auto" follows them: outdoors, or mapped at
    # `large_area_voxel_m` or coarser. (Their PLATFORM A crops are not taken: one large-area
    # tree for every area, docs/planners/esm.md.)
    large_outdoors: bool = True

    def large_tree_auto(self, voxel_size: float, indoor: bool) -> bool:
        return (self.large_outdoors and not indoor) or super().large_tree_auto(voxel_size, indoor)


class EsmReconHorizonConfig(EsmHorizonConfig):
    """ESM-Recon with the local horizon: the reconstruction gain."""

    gain: Literal["volumetric", "reconstruction"] = "reconstruction"


class EsmReconHorizonV3Config(EsmHorizonV3Config):
    """ESM-Recon v3: `EsmHorizonV3Config` with the reconstruction gain."""

    gain: Literal["volumetric", "reconstruction"] = "reconstruction"
