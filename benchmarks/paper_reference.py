"""The FLYBO paper's Tables 2 and 3 (transcribed) and its findings of sections 4.1-4.3, each
with the test that says whether a table of results holds it (`benchmarks/paper_findings.py`)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from server.leaderboard import ranks

AREAS = ("maze", "offices-a", "offices-b", "offices-c", "facility-a", "facility-b",
         "facility-c", "warehouse", "platform-a", "platform-b", "powerplant")
PLANNERS = ("classic", "rapid", "nbvp", "aep", "esm-ipp", "esm-recon", "splatplanner")
# Table 2 of the paper (volumetric coverage at the plateau, relative to the best, 5-run
# average), one row per planner in the order of AREAS.
PAPER_TABLE2 = {
    "classic": (0.9992, 0.9945, 0.9957, 0.9926, 0.9868, 0.9911, 0.9883, 0.9681, 0.9933,
                0.8795, 0.7484),
    "rapid": (0.9988, 0.994, 0.9987, 0.9912, 0.99, 0.9932, 0.995, 0.9861, 0.9934, 0.9995,
              0.9999),
    "nbvp": (0.9925, 0.9648, 0.9685, 0.9258, 0.9973, 0.9866, 0.9774, 0.9834, 0.9887, 0.9748,
             0.9587),
    "aep": (0.975, 0.9911, 0.9882, 0.9656, 0.9836, 0.9863, 0.9642, 0.9962, 0.9939, 0.993,
            0.9945),
    "esm-ipp": (0.9997, 1.0, 0.9962, 0.9976, 0.9961, 0.9925, 0.9971, 1.0, 1.0, 1.0, 1.0),
    "esm-recon": (1.0, 0.9953, 0.9988, 1.0, 1.0, 0.9927, 0.9974, 0.9974, 0.9863, 0.9758,
                  0.9001),
    "splatplanner": (0.9998, 0.9923, 1.0, 0.9935, 0.9959, 1.0, 1.0, 0.9952, 0.9976, 0.999,
                     0.9984),
}
# Table 3 of the paper: final mesh F-score (5-run average), areas in the order of AREAS ...
PAPER_TABLE3_FSCORE = {
    "classic": (0.9807, 0.9792, 0.9371, 0.9661, 0.9266, 0.9459, 0.9629, 0.7781, 0.8111,
                0.6738, 0.6694),
    "rapid": (0.9831, 0.9905, 0.9435, 0.962, 0.9257, 0.9477, 0.9574, 0.8097, 0.7912, 0.7597,
              0.8673),
    "nbvp": (0.9888, 0.9609, 0.9086, 0.916, 0.9257, 0.9351, 0.9416, 0.7289, 0.778, 0.7009,
             0.8251),
    "aep": (0.9362, 0.9687, 0.9182, 0.9385, 0.9132, 0.9353, 0.9214, 0.7581, 0.7647, 0.7616,
            0.8484),
    "esm-ipp": (0.9944, 0.982, 0.9344, 0.9575, 0.9338, 0.9429, 0.9613, 0.8077, 0.7028, 0.768,
                0.8513),
    "esm-recon": (0.9862, 0.9831, 0.9355, 0.9603, 0.9355, 0.9468, 0.9538, 0.7927, 0.7965,
                  0.7986, 0.8809),
    "splatplanner": (0.9848, 0.9891, 0.9391, 0.9597, 0.9201, 0.9527, 0.9602, 0.8118, 0.7576,
                     0.7575, 0.8674),
}
# ... and its RMSE in metres (the mean of each 'mean ± std' cell).
PAPER_TABLE3_RMSE = {
    "classic": (0.018, 0.019, 0.021, 0.015, 0.021, 0.02, 0.02, 0.03, 0.03, 0.046, 0.032),
    "rapid": (0.021, 0.018, 0.021, 0.016, 0.022, 0.02, 0.02, 0.029, 0.032, 0.043, 0.034),
    "nbvp": (0.018, 0.019, 0.023, 0.017, 0.021, 0.021, 0.022, 0.031, 0.037, 0.044, 0.034),
    "aep": (0.023, 0.021, 0.024, 0.017, 0.026, 0.021, 0.025, 0.032, 0.037, 0.043, 0.034),
    "esm-ipp": (0.016, 0.018, 0.021, 0.016, 0.019, 0.02, 0.02, 0.029, 0.036, 0.042, 0.036),
    "esm-recon": (0.018, 0.019, 0.022, 0.016, 0.02, 0.02, 0.021, 0.029, 0.031, 0.038, 0.031),
    "splatplanner": (0.02, 0.018, 0.021, 0.016, 0.022, 0.018, 0.021, 0.028, 0.033, 0.043,
                     0.033),
}
SMALL = ("maze", "offices-a", "offices-b", "offices-c", "facility-a", "facility-b")
LARGE = ("facility-c", "warehouse", "platform-a", "platform-b", "powerplant")

# Cells: {family: {area: {"relative": .., "fscore": .., "rmse": .., "recall": ..}}}
Cells = dict[str, dict[str, dict[str, float]]]



def average_ranks(cells: Cells, key: str, lower_is_better: bool = False) -> dict[str, float]:
    """Per area rank of each planner by `key` (1 best, ties share), averaged over the areas."""
    areas = sorted({a for by_area in cells.values() for a in by_area})
    sums: dict[str, list[float]] = {p: [] for p in cells}
    sign = -1.0 if lower_is_better else 1.0
    for area in areas:
        here = {p: sign * cells[p][area][key] for p in cells if key in cells[p].get(area, {})}
        for p, r in ranks(here).items():
            sums[p].append(r)
    return {p: float(np.mean(v)) for p, v in sums.items() if v}


def pareto(cov: dict[str, float], fs: dict[str, float]) -> set[str]:
    """The planners no other beats in both average ranks (the leaderboard's rule)."""
    return {p for p in cov if p in fs and not any(
        cov[q] <= cov[p] and fs[q] <= fs[p] and (cov[q] < cov[p] or fs[q] < fs[p])
        for q in cov if q in fs)}


Finding = tuple[str, str, Callable[[Cells], bool | None]]


def _mean(cells: Cells, planner: str, areas: tuple[str, ...], key: str) -> float | None:
    here = cells.get(planner, {})
    values = [here[a][key] for a in areas if key in here.get(a, {})]
    return float(np.mean(values)) if values else None


def _needs(cells: Cells, *planners: str) -> bool:
    return all(p in cells for p in planners)


def _top(order: dict[str, float], k: int, reverse: bool = False) -> list[str]:
    return sorted(order, key=lambda p: order[p], reverse=reverse)[:k]


def _all_planners(cells: Cells) -> bool:
    return set(PLANNERS) <= set(cells)


def _smaller_on_large(cells: Cells, planner: str, key: str) -> bool | None:
    if planner not in cells:
        return None
    small, large = _mean(cells, planner, SMALL, key), _mean(cells, planner, LARGE, key)
    return None if small is None or large is None else large < small


def _steady(cells: Cells) -> bool | None:
    steady = ("splatplanner", "aep", "nbvp", "esm-ipp", "esm-recon")
    if not _needs(cells, *steady):
        return None
    return all(v["relative"] >= 0.9 for p in steady for v in cells[p].values())


def _rapid_narrow(cells: Cells) -> bool | None:
    narrow = ("offices-c", "facility-b")
    if "rapid" not in cells or not any(a in cells["rapid"] for a in narrow):
        return None
    rest = tuple(a for a in cells["rapid"] if a not in narrow)
    there, elsewhere = (_mean(cells, "rapid", narrow, "relative"),
                        _mean(cells, "rapid", rest, "relative"))
    return None if there is None or elsewhere is None else there < elsewhere


def _by_rank(key: str, lower: bool, check: Callable[[dict[str, float]], bool]
             ) -> Callable[[Cells], bool | None]:
    def held(cells: Cells) -> bool | None:
        if not _all_planners(cells):
            return None
        order = average_ranks(cells, key, lower)
        # A score not measured for every planner (a crash sweep has no RMSE) decides nothing.
        return check(order) if set(PLANNERS) <= set(order) else None
    return held


def _pareto_held(cells: Cells) -> bool | None:
    if not _all_planners(cells):
        return None
    cov, fs = average_ranks(cells, "relative"), average_ranks(cells, "fscore")
    return pareto(cov, fs) == {"esm-ipp", "esm-recon", "splatplanner"}


def _compromise(cells: Cells) -> bool | None:
    if not _all_planners(cells):
        return None
    cov, fs = average_ranks(cells, "relative"), average_ranks(cells, "fscore")
    return ("splatplanner" in pareto(cov, fs) and _top(cov, 1)[0] != "splatplanner"
            and _top(fs, 1)[0] != "splatplanner")


def _classic_small(cells: Cells) -> bool | None:
    small = [a for a in (*SMALL, "facility-c") if a in cells.get("classic", {})]
    return all(cells["classic"][a]["relative"] >= 0.95 for a in small) if small else None


def _rapid_everywhere(cells: Cells) -> bool | None:
    return all(v["relative"] >= 0.95 for v in cells["rapid"].values()) \
        if "rapid" in cells else None


def _means(cells: Cells, key: str) -> dict[str, float] | None:
    """Each planner's mean of `key` over its areas; None unless every paper planner has it."""
    if not _all_planners(cells) or any(key not in v for c in cells.values() for v in c.values()):
        return None
    return {p: float(np.mean([v[key] for v in cells[p].values()])) for p in cells}


def _mean_worst(key: str, planner: str, lower: bool) -> Callable[[Cells], bool | None]:
    def held(cells: Cells) -> bool | None:
        means = _means(cells, key)
        return None if means is None else _top(means, 1, reverse=not lower)[0] == planner
    return held


def _recall_top(cells: Cells) -> bool | None:
    means = _means(cells, "recall")
    return None if means is None else set(_top(means, 2, reverse=True)) == {"esm-ipp",
                                                                           "splatplanner"}


def _aep_below_nbvp_rmse(cells: Cells) -> bool | None:
    if not _needs(cells, "aep", "nbvp"):
        return None
    shared = tuple(a for a in cells["aep"] if a in cells["nbvp"])
    aep, nbvp = _mean(cells, "aep", shared, "rmse"), _mean(cells, "nbvp", shared, "rmse")
    return None if aep is None or nbvp is None else aep > nbvp


FINDINGS: list[Finding] = [
    ("4.1", "SplatPlanner, AEP, NBVP, ESM-IPP, ESM-Recon are steady throughout "
     "(relative coverage >= 0.90 on every area)", _steady),
    ("4.1", "Classic struggles on the larger scenes (mean relative coverage on FACILITY C, "
     "WAREHOUSE, PLATFORM A-B, POWERPLANT below that on the smaller ones)",
     lambda c: _smaller_on_large(c, "classic", "relative")),
    ("4.1", "Rapid suffers on narrow, intricate OFFICES C and FACILITY B (below its mean "
     "elsewhere)", _rapid_narrow),
    ("4.1", "ESM-IPP is the clear coverage winner (best average coverage rank)",
     _by_rank("relative", False, lambda r: _top(r, 1) == ["esm-ipp"])),
    ("4.1", "followed by SplatPlanner and ESM-Recon (2nd and 3rd average coverage rank)",
     _by_rank("relative", False, lambda r: set(_top(r, 3)[1:]) == {"splatplanner",
                                                                   "esm-recon"})),
    ("4.1", "NBVP and AEP perform the worst (two worst average coverage ranks)",
     _by_rank("relative", False, lambda r: set(_top(r, 2, True)) == {"nbvp", "aep"})),
    ("4.1", "Classic is competitive rank-wise (average coverage rank better than NBVP's and "
     "AEP's)", _by_rank("relative", False,
                        lambda r: r["classic"] < min(r["nbvp"], r["aep"]))),
    ("4.1", "Classic performs especially well on MAZE, OFFICES A-C, FACILITY A-C (relative "
     "coverage >= 0.95 on each)", _classic_small),
    ("4.1", "Rapid is competitive throughout (relative coverage >= 0.95 on every area)",
     _rapid_everywhere),
    ("4.2", "surface coverage: Classic drops on the larger areas (mean surface recall on the "
     "large ones below that on the smaller ones)",
     lambda c: _smaller_on_large(c, "classic", "recall")),
    ("4.2", "surface coverage: NBVP is the worst overall (lowest mean surface recall)",
     _mean_worst("recall", "nbvp", lower=True)),
    ("4.2", "surface coverage: ESM-IPP and SplatPlanner top (two highest mean recalls)",
     _recall_top),
    ("4.2", "ESM-IPP has the best RMSE (best average RMSE rank)",
     _by_rank("rmse", True, lambda r: _top(r, 1) == ["esm-ipp"])),
    ("4.2", "ESM-Recon has the best F-score (best average F-score rank)",
     _by_rank("fscore", False, lambda r: _top(r, 1) == ["esm-recon"])),
    ("4.2", "closely followed by Rapid and SplatPlanner (2nd and 3rd average F-score rank)",
     _by_rank("fscore", False, lambda r: set(_top(r, 3)[1:]) == {"rapid", "splatplanner"})),
    ("4.2", "AEP is worse than NBVP in RMSE (higher mean RMSE)", _aep_below_nbvp_rmse),
    ("4.2", "AEP is almost as bad as NBVP in F-score (the two worst average F-score ranks)",
     _by_rank("fscore", False, lambda r: set(_top(r, 2, True)) == {"nbvp", "aep"})),
    ("4.3", "the Pareto set is ESM-IPP, ESM-Recon and SplatPlanner", _pareto_held),
    ("4.3", "SplatPlanner is the compromise: in the Pareto set, leading neither coverage nor "
     "F-score", _compromise),
]


def findings(cells: Cells) -> list[dict[str, str]]:
    out = []
    for section, text, check in FINDINGS:
        verdict = check(cells)
        out.append({"section": section, "finding": text,
                    "status": "not measured" if verdict is None
                    else ("held" if verdict else "not held")})
    return out

