"""Imports of the real buildings with thin parts: the AWS RoboMaker small house, bookstore and
small warehouse.

``small_house.ply``, ``bookstore.ply`` and ``small_warehouse.ply`` in ``tests/data/meshes`` are
assembled from the AWS RoboMaker worlds by Amazon.com, Inc. or its affiliates, licensed under
MIT No Attribution (see the README.md beside them; ``benchmarks/gazebo_world_mesh.py`` rebuilds
them).

Each thin part below is a voxel centre found in the shipped file: the voxel is blocked and in
the ground truth's observable set (its surface is seen from where the vehicle flies), and along
each named axis the run of blocked voxels through it is at most two voxels long and ends in
free voxels that are seen too, so that a chair leg or a shelf is told from the side of a closed
piece of furniture or an outer wall, whose surface is seen from one side only (checked too).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from areas.area import Area, GroundTruth
from areas.ground_truth import blocked_voxels, compute_ground_truth
from areas.importer import import_mesh

MESHES = Path(__file__).resolve().parents[1] / "data" / "meshes"
MAX_THIN_VOXELS = 2  # 0.2 m at the default 0.1 m voxel


@dataclass(frozen=True)
class ThinPart:
    what: str
    point: tuple[float, float, float]  # a voxel centre, metres
    axes: tuple[int, ...]  # along which the part is thin (0 x, 1 y, 2 z)


@dataclass(frozen=True)
class Building:
    file: str
    name: str
    extent: tuple[float, float, float]  # metres, of the vertices
    faces: int  # after the importer drops degenerate faces
    min_reachable_m3: float
    indoor: bool  # whether the space the vehicle reaches is under a roof (areas/auto_start.py)
    thin_parts: tuple[ThinPart, ...]
    one_sided: ThinPart  # a surface voxel seen from one side only: not a thin part


SMALL_HOUSE = Building(
    "small_house.ply", "small-house", (19.0, 11.4, 3.0), 105_913, 150.0, True,
    (
        ThinPart("leg of the reading chair (2.6 cm)", (-8.45, 2.15, 0.25), (0, 1)),
        ThinPart("another leg of the reading chair", (-8.15, 2.15, 0.25), (0, 1)),
        ThinPart("kitchen table top", (6.55, 0.95, 0.85), (2,)),
        ThinPart("shoe rack shelf", (4.25, -5.05, 0.35), (2,)),
        ThinPart("cable of the bedroom chandelier (1-4 mm)", (-6.45, -0.85, 2.35), (0,)),
        ThinPart("cable of the balcony chandelier", (1.25, 3.95, 1.75), (0,)),
        ThinPart("folding door (9 cm)", (-2.45, 1.15, 1.05), (0,)),
    ),
    ThinPart("outer wall", (-9.45, 0.05, 1.25), (0,)),
)
BOOKSTORE = Building(
    "bookstore.ply", "bookstore", (15.7, 14.61, 3.72), 118_189, 250.0, True,
    (
        ThinPart("tube of a bar chair (3.3 cm)", (-4.75, 5.05, 0.45), (0, 1)),
        ThinPart("another tube of that chair", (-4.65, 4.85, 0.45), (0, 1)),
        ThinPart("top of a long table", (-5.75, 1.55, 0.95), (2,)),
        ThinPart("tablet on its stand (1 cm)", (-1.85, 0.55, 1.25), (1,)),
    ),
    ThinPart("side of a closed display table", (-4.05, 3.15, 0.45), (0,)),
)
SMALL_WAREHOUSE = Building(
    "small_warehouse.ply", "small-warehouse", (14.0, 20.92, 10.21), 14_997, 1500.0, True,
    (
        ThinPart("upright of a shelving rack (4.5 x 2.6 cm)", (2.75, 0.15, 0.35), (0, 1)),
        ThinPart("brace in the rack's middle frame", (4.75, 0.55, 0.45), (0, 1)),
        ThinPart("handle of the pallet jack (2.6 x 4.7 cm)", (-0.75, -9.55, 0.85), (0, 1)),
    ),
    ThinPart("outer wall", (-6.85, 0.05, 1.25), (0,)),
)


@dataclass(frozen=True)
class Imported:
    building: Building
    area: Area
    truth: GroundTruth
    blocked: npt.NDArray[np.bool_]


BUILDINGS = (SMALL_HOUSE, BOOKSTORE, SMALL_WAREHOUSE)


@pytest.fixture(scope="module", params=BUILDINGS, ids=lambda b: b.name)
def imported(request: pytest.FixtureRequest,
             tmp_path_factory: pytest.TempPathFactory) -> Iterator[Imported]:
    building: Building = request.param
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("FLYBO_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))
        area = import_mesh(MESHES / building.file, building.name)
        yield Imported(building, area, compute_ground_truth(area), blocked_voxels(area))


def _voxel(area: Area, point: npt.NDArray[np.float64]) -> tuple[int, int, int]:
    i, j, k = np.floor((point - area.bounds_min) / area.voxel_size).astype(int)
    return int(i), int(j), int(k)


def _blocked_run(blocked: npt.NDArray[np.bool_], voxel: tuple[int, int, int],
                 axis: int) -> tuple[int, list[tuple[int, int, int]]]:
    """Length of the run of blocked voxels through ``voxel`` along ``axis``, and the free
    voxel at each end."""
    length, ends = 1, []
    for step in (-1, 1):
        cur = list(voxel)
        while True:
            cur[axis] += step
            end = (cur[0], cur[1], cur[2])
            if not blocked[end]:
                ends.append(end)
                break
            length += 1
    return length, ends


def _not_thin_because(imported: Imported, part: ThinPart) -> str | None:
    """Why ``part`` is no thin part in the ground truth (None when it is one)."""
    voxel = _voxel(imported.area, np.array(part.point))
    if not imported.blocked[voxel]:
        return f"{part.what}: voxel {voxel} is free"
    if not imported.truth.observable[voxel]:
        return f"{part.what}: voxel {voxel} is not seen"
    for axis in part.axes:
        length, ends = _blocked_run(imported.blocked, voxel, axis)
        if length > MAX_THIN_VOXELS:
            return f"{part.what}: {length} voxels thick along axis {axis}"
        unseen = [end for end in ends if not imported.truth.observable[end]]
        if unseen:
            return f"{part.what}: the free voxels {unseen} beside it are not seen"
    return None


@pytest.mark.slow  # a real building's import and ground truth
def test_imports_in_metres_and_is_explorable(imported: Imported) -> None:
    area, building = imported.area, imported.building
    np.testing.assert_allclose(np.ptp(area.vertices, axis=0), building.extent, atol=0.01)
    assert len(area.triangles) == building.faces
    assert area.info.complexity == "imported"
    assert area.info.indoor == building.indoor
    # The start is inside the building: within its walls, below its ceiling, in free space.
    lo, hi = area.vertices.min(axis=0), area.vertices.max(axis=0)
    assert np.all(area.start.position[:2] > lo[:2] + 1.0)
    assert np.all(area.start.position[:2] < hi[:2] - 1.0)
    assert lo[2] + 1.0 <= area.start.position[2] <= hi[2] - 1.0
    assert not imported.blocked[_voxel(area, area.start.position)]
    assert imported.truth.reachable_volume_m3 >= building.min_reachable_m3
    assert 300.0 <= area.plateau_s <= 1800.0


@pytest.mark.slow  # a real building's import and ground truth
def test_thin_parts_are_in_the_ground_truth(imported: Imported) -> None:
    for part in imported.building.thin_parts:
        assert _not_thin_because(imported, part) is None, _not_thin_because(imported, part)
    # Blocked, seen and at most two voxels thick too, but with unseen space behind it.
    reason = _not_thin_because(imported, imported.building.one_sided)
    assert reason is not None and reason.endswith("beside it are not seen"), reason
