"""The share of the reachable space under a surface: the rule that classes an imported area.

    .venv/bin/python benchmarks/indoor_share.py [AREA ...]

For each area (default: the 11 built-in ones; imported ones by name), the share of the space the
vehicle reaches from the start that has a surface somewhere above it
(`areas.auto_start.covered_fraction`), the class the importer's rule gives
(`INDOOR_MIN_COVERED`), and the area's own class (Table 1's for the built-in areas). Writes
`benchmarks/results/indoor_share.json`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from areas import area_names, load_area
from areas.auto_start import INDOOR_MIN_COVERED, covered_fraction
from areas.ground_truth import blocked_voxels
from areas.observability import ViewModel, traversable
from benchmarks.common import print_table, write_json


def reachable_share(name: str) -> tuple[float, bool]:
    """(covered share of the reachable space, the area's own class: indoor)."""
    area = load_area(name)
    vs = area.voxel_size
    blocked = blocked_voxels(area)
    labels, _ = ndimage.label(traversable(blocked, vs, ViewModel().safety_radius_m))
    start = np.floor((area.start.position - area.bounds_min) / vs).astype(int)
    label = labels[tuple(start)]
    if label == 0:  # the start voxel itself is not traversable: its nearest traversable one
        cells = np.argwhere(labels > 0)
        label = labels[tuple(cells[np.linalg.norm(cells - start, axis=1).argmin()])]
    return covered_fraction(blocked, labels == label), area.info.indoor


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("areas", nargs="*")
    args = parser.parse_args()
    names = args.areas or area_names()
    rows, payload = [], {}
    for name in names:
        share, indoor = reachable_share(name)
        ruled = share >= INDOOR_MIN_COVERED
        payload[name] = {"covered_share": share, "rule_indoor": ruled, "indoor": indoor}
        rows.append([name, f"{share:.3f}", "indoor" if ruled else "outdoor",
                     "indoor" if indoor else "outdoor"])
    print_table(f"Reachable space under a surface (indoor at {INDOOR_MIN_COVERED:g} or more)",
                ["area", "covered share", "the rule", "the area's class"], rows)
    write_json("indoor_share", payload)


if __name__ == "__main__":
    main()
