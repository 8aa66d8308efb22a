"""The built-in planners, registered in one place."""

from __future__ import annotations

from planners.aep import Aep, AepV1
from planners.classic import Classic
from planners.esm import Esm, EsmRecon
from planners.nbvp import Nbvp
from planners.rapid import Rapid
from planners.registry import register
from planners.splat import SplatPlanner

register(
    "classic",
    1,
    Classic,
    description="Nearest frontier by path length (Yamauchi 1997), replanned at every waypoint.",
    reference="B. Yamauchi, A frontier-based approach for autonomous exploration, CIRA 1997",
)
register(
    "rapid",
    1,
    Rapid,
    description="Frontier in view needing the least change of velocity direction, flown at full "
    "speed and replanned in flight; nearest frontier otherwise.",
    reference="T. Cieslewski, E. Kaufmann, D. Scaramuzza, Rapid exploration with multi-rotors: "
    "a frontier selection method for high speed flight, IROS 2017",
)
register(
    "nbvp",
    1,
    Nbvp,
    description="Receding-horizon next-best-view: RRT with discounted view gains, first edge of "
    "the best branch.",
    reference="A. Bircher, M. Kamel, K. Alexis, H. Oleynikova, R. Siegwart, Receding horizon "
    "'next-best-view' planner for 3D exploration, ICRA 2016",
)
_AEP_REFERENCE = ("M. Selin, M. Tiger, D. Duberg, F. Heintz, P. Jensfelt, Efficient "
                  "autonomous exploration planning of large-scale 3-D environments, RA-L 2019")
register(
    "aep",
    1,
    AepV1,
    description="NBVP-like local RRT* with best yaws, plus cached high-gain nodes revisited "
    "when the local gain runs out; ends when no cached node is worth visiting.",
    reference=_AEP_REFERENCE,
)
register(
    "aep",
    2,
    Aep,
    description="NBVP-like local RRT* with best yaws, plus cached high-gain nodes revisited "
    "when the local gain runs out, and the nearest frontier when none is worth visiting.",
    reference=_AEP_REFERENCE,
)
register(
    "splatplanner",
    1,
    SplatPlanner,
    description="Frontier voxels (position, normal) filtered on a permutohedral lattice; the "
    "viewpoint with the best filtered frontier density per flight time, reached by A*.",
    reference="A. Brunel, A. Bourki, C. Demonceaux, O. Strauss, SplatPlanner: efficient "
    "autonomous exploration via permutohedral frontier filtering, ICRA 2021",
)
register(
    "esm-ipp",
    1,
    Esm,
    description="One persistent RRT* tree of segments grown at every call, valued by the "
    "unknown volume seen per second of flight along each branch; flies the best root child, "
    "re-roots there, recomputes stale gains lazily, back-tracks when nothing is worth flying.",
    reference="L. Schmid, M. Pantic, R. Khanna, L. Ott, R. Siegwart, J. Nieto, An efficient "
    "sampling-based method for online informative path planning in unknown environments, "
    "RA-L 2020",
)
register(
    "esm-recon",
    1,
    EsmRecon,
    description="ESM with a reconstruction gain: surface voxels seen by few fused frames or "
    "from few directions, plus unknown volume, per second of flight.",
    reference="L. Schmid, M. Pantic, R. Khanna, L. Ott, R. Siegwart, J. Nieto, An efficient "
    "sampling-based method for online informative path planning in unknown environments, "
    "RA-L 2020",
)
