"""The built-in planners: every id and version in one place.

`BUILTINS` is data: the registry (`planners.registry`) registers it exactly once, before any
other registration or lookup; importing this module registers nothing, and it does not import
the registry.

A registered id keeps its code: a change of a planner's behaviour is registered as a new version
beside the old one (a new config model, or a flag of the shared class), never as an edit of the
old one. `flybo.versions` fingerprints every id, and `tests/test_versions.py` holds the
fingerprints to the lock file (`python -m flybo.versions --write` updates it).
"""

from __future__ import annotations

from planners.aep import Aep, AepV1, AepV3, AepV4
from planners.api import Planner
from planners.classic import Classic, ClassicV2, ClassicV3
from planners.esm import EsmRecon, EsmV1
from planners.esm_continuous import EsmContinuous, EsmReconContinuous
from planners.esm_horizon import EsmHorizon, EsmHorizonV3, EsmReconHorizon, EsmReconHorizonV3
from planners.falcon import Falcon, FalconV2
from planners.fidelity import ORIGINAL, VARIANT
from planners.fuel import Fuel, FuelV2
from planners.nbvp import Nbvp, NbvpV2
from planners.rapid import Rapid, RapidV2
from planners.splat import SplatPlanner, SplatPlannerV2

_CLASSIC_REFERENCE = "B. Yamauchi, A frontier-based approach for autonomous exploration, CIRA 1997"
_RAPID_REFERENCE = ("T. Cieslewski, E. Kaufmann, D. Scaramuzza, Rapid exploration with "
                    "multi-rotors: a frontier selection method for high speed flight, IROS 2017")
_SPLAT_REFERENCE = ("A. Brunel, A. Bourki, C. Demonceaux, O. Strauss, SplatPlanner: efficient "
                    "autonomous exploration via permutohedral frontier filtering, ICRA 2021")
_NBVP_REFERENCE = ("A. Bircher, M. Kamel, K. Alexis, H. Oleynikova, R. Siegwart, Receding horizon "
                   "'next-best-view' planner for 3D exploration, ICRA 2016")
_AEP_REFERENCE = ("M. Selin, M. Tiger, D. Duberg, F. Heintz, P. Jensfelt, Efficient "
                  "autonomous exploration planning of large-scale 3-D environments, RA-L 2019")
_FUEL_REFERENCE = ("B. Zhou, Y. Zhang, X. Chen, S. Shen, FUEL: fast UAV exploration using "
                   "incremental frontier structure and hierarchical planning, RA-L 2021")
_FALCON_REFERENCE = ("Y. Zhang, X. Chen, C. Feng, B. Zhou, S. Shen, FALCON: fast autonomous aerial "
                     "exploration using coverage path guidance, T-RO 2024")
_ESM_REFERENCE = ("L. Schmid, M. Pantic, R. Khanna, L. Ott, R. Siegwart, J. Nieto, An efficient "
                  "sampling-based method for online informative path planning in unknown "
                  "environments, RA-L 2020")

# `method` (`planners.fidelity`): what each version is to its paper; the reason for every
# variant is in `docs/planners.md`, "Original methods and variants".
# (name, version, class, method, description, reference)
BUILTINS: tuple[tuple[str, int, type[Planner], str, str, str], ...] = (
    (
        "classic", 1, Classic, ORIGINAL,
        "Nearest frontier by path length (Yamauchi 1997), replanned at every waypoint.",
        _CLASSIC_REFERENCE,
    ),
    (
        "classic", 2, ClassicV2, ORIGINAL,
        "Nearest unvisited frontier by path length (Yamauchi 1997), replanned at every "
        "waypoint; the frontier looked at from a reached viewpoint counts as visited, and a "
        "vehicle the map closed in on escapes through known free space.",
        _CLASSIC_REFERENCE,
    ),
    (
        "classic", 3, ClassicV3, ORIGINAL,
        "As classic-v2, with the path shortcut from the vehicle's exact position, so that it "
        "never flies back to its voxel's centre to ask again.",
        _CLASSIC_REFERENCE,
    ),
    (
        "rapid", 1, Rapid, ORIGINAL,
        "Frontier in view needing the least change of velocity direction, flown at full "
        "speed and replanned in flight; nearest frontier otherwise.",
        _RAPID_REFERENCE,
    ),
    (
        "rapid", 2, RapidV2, ORIGINAL,
        "As rapid-v1, with classic-v2's nearest unvisited frontier as the fallback.",
        _RAPID_REFERENCE,
    ),
    (
        "nbvp", 1, Nbvp, VARIANT,
        "Receding-horizon next-best-view: RRT with discounted view gains, first edge of "
        "the best branch.",
        _NBVP_REFERENCE,
    ),
    (
        "nbvp", 2, NbvpV2, ORIGINAL,
        "Receding-horizon next-best-view as published: one RRT sampled in the whole area, "
        "gains cast through the map as it is, first edge of the best branch.",
        _NBVP_REFERENCE,
    ),
    (
        "aep", 1, AepV1, VARIANT,
        "NBVP-like local RRT* with best yaws, plus cached high-gain nodes revisited "
        "when the local gain runs out; ends when no cached node is worth visiting.",
        _AEP_REFERENCE,
    ),
    (
        "aep", 2, Aep, VARIANT,
        "NBVP-like local RRT* with best yaws, plus cached high-gain nodes revisited "
        "when the local gain runs out, and the nearest frontier when none is worth visiting.",
        _AEP_REFERENCE,
    ),
    (
        "aep", 3, AepV3, VARIANT,
        "As aep-v2, with classic-v2's nearest unvisited frontier when no cached node is "
        "worth visiting.",
        _AEP_REFERENCE,
    ),
    (
        "aep", 4, AepV4, ORIGINAL,
        "NBVP-like local RRT* with best yaws; when the local gain runs out, the nearest "
        "cached node whose cached gain exceeds 16 m³ (gains refreshed near the vehicle every "
        "5 s), as the public code the FLYBO authors ran; with none, it hovers and plans again.",
        _AEP_REFERENCE,
    ),
    (
        "splatplanner", 1, SplatPlanner, ORIGINAL,
        "Frontier voxels (position, normal) filtered on a permutohedral lattice; the "
        "viewpoint with the best filtered frontier density per flight time, reached by A*.",
        _SPLAT_REFERENCE,
    ),
    (
        "splatplanner", 2, SplatPlannerV2, ORIGINAL,
        "As splatplanner-v1, with classic-v2's nearest unvisited frontier as the fallback.",
        _SPLAT_REFERENCE,
    ),
    (
        "esm-ipp", 1, EsmV1, VARIANT,
        "One persistent RRT* tree of segments grown at every call, valued by the "
        "unknown volume seen per second of flight along each branch; flies the best root child, "
        "re-roots there, recomputes stale gains lazily, back-tracks when nothing is worth flying.",
        _ESM_REFERENCE,
    ),
    (
        "esm-recon", 1, EsmRecon, VARIANT,
        "ESM with a reconstruction gain: surface voxels seen by few fused frames or "
        "from few directions, plus unknown volume, per second of flight.",
        _ESM_REFERENCE,
    ),
    (
        "esm-ipp", 2, EsmHorizon, VARIANT,
        "As esm-ipp-v1, with the original's local horizon: only views within the update range "
        "of the vehicle are re-evaluated, no segment is shorter than the minimum length, and "
        "areas mapped at 0.2 m grow the FLYBO authors' large-area tree (3 m segments).",
        _ESM_REFERENCE,
    ),
    (
        "esm-recon", 2, EsmReconHorizon, VARIANT,
        "As esm-recon-v1, with esm-ipp-v2's local horizon, minimum segment length and "
        "large-area tree.",
        _ESM_REFERENCE,
    ),
    (
        "esm-ipp", 3, EsmHorizonV3, VARIANT,
        "As esm-ipp-v2, and outdoor areas (the area's class in the planner's context) grow "
        "the large-area tree too, as the FLYBO authors' PLATFORM A configuration does.",
        _ESM_REFERENCE,
    ),
    (
        "esm-recon", 3, EsmReconHorizonV3, VARIANT,
        "As esm-recon-v2, with esm-ipp-v3's large-area tree on outdoor areas.",
        _ESM_REFERENCE,
    ),
    (
        "esm-ipp", 4, EsmContinuous, ORIGINAL,
        "As esm-ipp-v3, growing the tree while the vehicle flies (asked mid-leg once the "
        "flight is under way), as the original expands continuously; at a segment's end it "
        "only selects.",
        _ESM_REFERENCE,
    ),
    (
        "esm-recon", 4, EsmReconContinuous, ORIGINAL,
        "As esm-recon-v3, growing the tree while the vehicle flies, as esm-ipp-v4.",
        _ESM_REFERENCE,
    ),
    (
        "fuel", 1, Fuel, ORIGINAL,
        "Frontier clusters with coverage-ranked viewpoints, a global ATSP tour over their "
        "best viewpoints by flight time, the next few clusters' viewpoints refined by a graph "
        "search; replanned in flight.",
        _FUEL_REFERENCE,
    ),
    (
        "fuel", 2, FuelV2, VARIANT,
        "As fuel-v1, but a frontier cluster without viewpoints samples them again at every "
        "call, where fuel-v1 keeps it dormant until its voxels change.",
        _FUEL_REFERENCE,
    ),
    (
        "falcon", 1, Falcon, ORIGINAL,
        "FUEL's frontier clusters guided by a coverage path: the explored map cut into cells "
        "and their free and unknown zones with a connectivity graph, an ATSP tour over the "
        "zones, the nearby frontiers ordered by a sequential ordering problem that keeps the "
        "tour's order; replanned in flight.",
        _FALCON_REFERENCE,
    ),
    (
        "falcon", 2, FalconV2, VARIANT,
        "As falcon-v1, but a frontier cluster without viewpoints samples them again at every "
        "call, as fuel-v2.",
        _FALCON_REFERENCE,
    ),
)

