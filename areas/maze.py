"""MAZE: a one-level 10 x 10 cell maze of 2 m cells, 20 x 20 x 2.5 m.

The layout is a perfect maze (a randomized depth-first spanning tree of the cell graph) with a few
extra openings so that it has loops. The mesh is the boundary of the free space: floor, ceiling and
wall faces, watertight, with normals pointing into the free space.

Construction: a rectilinear plan grid whose x and y breaks alternate wall strips (0.25 m, 0.125 m at
the outer edges) and cell interiors (1.75 m). Plan cell (a, b) with both indices odd is a cell
interior; one even and one odd is a passage strip between two maze cells (free when they are
connected); both even is a wall-strip crossing (always wall). Free plan cells get a floor and a
ceiling quad, and every edge between a free and a wall plan cell gets a vertical quad. All
vertices sit on the plan grid at z = 0 or z = height, so adjacent faces share whole edges.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from areas.area import Area, AreaInfo, StartPose

# Bump when a change to this module changes the generated area (names its ground-truth cache).
GENERATOR_VERSION = 1
CELLS = 10
CELL_SIZE = 2.0
# 0.25 m puts every wall face mid-voxel on the 0.1 m grid: a face on a voxel boundary would make
# which voxel a wall hit lands in a matter of floating-point rounding.
WALL_THICKNESS = 0.25
HEIGHT = 2.5
EXTRA_OPENINGS = 8
START_HEIGHT = 1.2

BoolArray = npt.NDArray[np.bool_]


def maze_passages(
    rng: np.random.Generator, cells: int = CELLS, extra_openings: int = EXTRA_OPENINGS
) -> tuple[BoolArray, BoolArray]:
    """Open walls of a maze on a ``cells`` x ``cells`` grid.

    Returns:
        open_x: (cells - 1, cells) bool, ``open_x[i, j]`` joins cell (i, j) and (i + 1, j).
        open_y: (cells, cells - 1) bool, ``open_y[i, j]`` joins cell (i, j) and (i, j + 1).
    """
    open_x = np.zeros((cells - 1, cells), dtype=bool)
    open_y = np.zeros((cells, cells - 1), dtype=bool)
    visited = np.zeros((cells, cells), dtype=bool)
    stack = [(0, 0)]
    visited[0, 0] = True
    while stack:
        i, j = stack[-1]
        options = [
            (di, dj)
            for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1))
            if 0 <= i + di < cells and 0 <= j + dj < cells and not visited[i + di, j + dj]
        ]
        if not options:
            stack.pop()
            continue
        di, dj = options[int(rng.integers(len(options)))]
        if di:
            open_x[min(i, i + di), j] = True
        else:
            open_y[i, min(j, j + dj)] = True
        visited[i + di, j + dj] = True
        stack.append((i + di, j + dj))

    # Knock out a few of the remaining walls so that the maze has loops.
    closed = [("x", int(a), int(b)) for a, b in np.argwhere(~open_x)]
    closed += [("y", int(a), int(b)) for a, b in np.argwhere(~open_y)]
    picks = rng.choice(len(closed), size=min(extra_openings, len(closed)), replace=False)
    for p in picks:
        axis, a, b = closed[int(p)]
        (open_x if axis == "x" else open_y)[a, b] = True
    return open_x, open_y


def plan_free(open_x: BoolArray, open_y: BoolArray) -> BoolArray:
    """Free plan cells of the strip grid.

    Args:
        open_x: (n - 1, n) bool passages along x, see `maze_passages`.
        open_y: (n, n - 1) bool passages along y.

    Returns:
        (2n + 1, 2n + 1) bool, True where the plan cell is free space.
    """
    n = open_y.shape[0]
    free = np.zeros((2 * n + 1, 2 * n + 1), dtype=bool)
    free[1::2, 1::2] = True
    free[2:-1:2, 1::2] = open_x
    free[1::2, 2:-1:2] = open_y
    return free


def plan_breaks(cells: int = CELLS) -> npt.NDArray[np.float64]:
    """(2 cells + 2,) plan grid coordinates along one axis, metres."""
    half = WALL_THICKNESS / 2.0
    walls = np.arange(cells + 1) * CELL_SIZE
    lower = np.clip(walls - half, 0.0, None)
    upper = np.clip(walls + half, None, cells * CELL_SIZE)
    # lower[0] == 0 and upper[-1] == the outer edge; the rest interleave wall and interior.
    return np.concatenate([[0.0], np.stack([upper[:-1], lower[1:]], axis=1).ravel(),
                           [cells * CELL_SIZE]])


def extrude_plan(
    free: BoolArray, breaks: npt.NDArray[np.float64], height: float
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int32]]:
    """Boundary mesh of the free plan cells extruded from z = 0 to ``height``.

    Args:
        free: (m, m) bool free plan cells; the border cells must be walls.
        breaks: (m + 1,) plan grid coordinates, shared by x and y.
        height: ceiling height in metres.

    Returns:
        vertices: (V, 3) float64, only the grid points used by faces.
        triangles: (F, 3) int32, counter-clockwise seen from the free space.
    """
    m = free.shape[0]
    g = m + 1

    def vid(a: npt.NDArray[np.int64], b: npt.NDArray[np.int64], top: int) -> npt.NDArray[np.int64]:
        return (top * g + a) * g + b

    quads: list[npt.NDArray[np.int64]] = []
    a, b = np.nonzero(free)
    # Corners in x-y counter-clockwise order seen from +z.
    c00, c10, c11, c01 = vid(a, b, 0), vid(a + 1, b, 0), vid(a + 1, b + 1, 0), vid(a, b + 1, 0)
    quads.append(np.stack([c00, c10, c11, c01], axis=1))  # floor, normal +z
    quads.append(np.stack([c00, c01, c11, c10], axis=1) + g * g)  # ceiling, normal -z

    # Vertical faces on edges between free and wall cells, facing into the free cell.
    wall_at = ~free
    # Free cell (a, b) with a wall at a - 1: face at x = breaks[a], normal +x.
    a, b = np.nonzero(free[1:, :] & wall_at[:-1, :])
    a = a + 1
    quads.append(np.stack([vid(a, b, 0), vid(a, b + 1, 0), vid(a, b + 1, 1), vid(a, b, 1)], 1))
    # Free cell with a wall at a + 1: face at x = breaks[a + 1], normal -x.
    a, b = np.nonzero(free[:-1, :] & wall_at[1:, :])
    quads.append(np.stack([vid(a + 1, b + 1, 0), vid(a + 1, b, 0), vid(a + 1, b, 1),
                           vid(a + 1, b + 1, 1)], 1))
    # Free cell with a wall at b - 1: face at y = breaks[b], normal +y.
    a, b = np.nonzero(free[:, 1:] & wall_at[:, :-1])
    b = b + 1
    quads.append(np.stack([vid(a + 1, b, 0), vid(a, b, 0), vid(a, b, 1), vid(a + 1, b, 1)], 1))
    # Free cell with a wall at b + 1: face at y = breaks[b + 1], normal -y.
    a, b = np.nonzero(free[:, :-1] & wall_at[:, 1:])
    quads.append(np.stack([vid(a, b + 1, 0), vid(a + 1, b + 1, 0), vid(a + 1, b + 1, 1),
                           vid(a, b + 1, 1)], 1))

    q = np.concatenate(quads)
    tri = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    used, tri_compact = np.unique(tri, return_inverse=True)
    top, rest = np.divmod(used, g * g)
    ia, ib = np.divmod(rest, g)
    vertices = np.stack([breaks[ia], breaks[ib], top * height], axis=1).astype(np.float64)
    return vertices, tri_compact.reshape(-1, 3).astype(np.int32)


def build_maze(seed: int = 0) -> Area:
    """The MAZE area for a given layout seed; the same seed gives identical arrays."""
    rng = np.random.default_rng(seed)
    open_x, open_y = maze_passages(rng)
    vertices, triangles = extrude_plan(plan_free(open_x, open_y), plan_breaks(), HEIGHT)

    # Face an open neighbour of cell (0, 0): +x (yaw 0) or else +y (yaw pi/2).
    yaw = 0.0 if open_x[0, 0] else float(np.pi / 2.0)
    start = StartPose(
        position=np.array([CELL_SIZE / 2.0, CELL_SIZE / 2.0, START_HEIGHT]), yaw=yaw
    )
    side = CELLS * CELL_SIZE
    return Area(
        name="maze",
        vertices=vertices,
        triangles=triangles,
        bounds_min=np.zeros(3),
        bounds_max=np.array([side, side, HEIGHT]),
        start=start,
        plateau_s=700.0,
        voxel_size=0.1,
        info=AreaInfo(title="MAZE", rooms=None, levels=1, complexity="low", indoor=True),
        cache_key=f"maze-g{GENERATOR_VERSION}-s{seed}",
    )
