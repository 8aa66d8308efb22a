"""Closed mesh primitives: each one watertight, wound outward, of the expected size."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from areas.primitives import (
    Mesh,
    Parts,
    beams,
    boxes,
    concat,
    cylinders,
    lathe,
    pipe_run,
    railing,
    rects_minus_holes,
    slab,
    stairs,
    wall,
)


def _components(mesh: Mesh) -> list[trimesh.Trimesh]:
    return trimesh.Trimesh(mesh.vertices, mesh.triangles, process=False).split(
        only_watertight=False
    )


def _assert_closed_outward(mesh: Mesh) -> None:
    parts = _components(mesh)
    assert parts
    for part in parts:
        assert part.is_watertight
        assert part.is_winding_consistent
        assert part.volume > 0.0  # outward normals


def test_box_volume_and_orientation() -> None:
    mesh = boxes([0, 0, 0], [1, 2, 3])
    _assert_closed_outward(mesh)
    assert _components(mesh)[0].volume == pytest.approx(6.0)
    with pytest.raises(ValueError, match="zero or negative"):
        boxes([0, 0, 0], [1, 0, 1])


def test_cylinder_and_lathe_volumes() -> None:
    cyl = cylinders([[0, 0, 0]], [[1, 2, 2]], 0.5, segments=64)
    _assert_closed_outward(cyl)
    assert _components(cyl)[0].volume == pytest.approx(np.pi * 0.25 * 3.0, rel=0.01)
    solid = lathe([[1.0, 0.0], [1.0, 2.0]], [[5.0, 5.0, 0.0], [9.0, 5.0, 0.0]], segments=64)
    _assert_closed_outward(solid)
    assert len(_components(solid)) == 2
    assert _components(solid)[0].volume == pytest.approx(2.0 * np.pi, rel=0.01)


@pytest.mark.parametrize("mesh", [
    beams([[0, 0, 0]], [[1, 2, 3]], 0.1, 0.2),
    slab((0, 0, 10, 10), 0.0, 0.2, [(2, 2, 4, 5)]),
    wall(0, 0.0, 10.0, 0.1, 0.2, 0.0, 3.0, [(2.0, 0.0, 3.4, 2.2)]),
    stairs([0, 0, 0], 0, 1.0, 1.0, 3.0),
    railing([[0, 0, 0], [5, 0, 0], [5, 3, 0]]),
    pipe_run(np.array([[0, 0, 1], [5, 0, 1], [5, 5, 1]], dtype=float), 0.1, 16, 1.0, 8),
])
def test_composite_parts_are_closed_components(mesh: Mesh) -> None:
    _assert_closed_outward(mesh)


def test_rects_minus_holes_cover_exactly_the_rest() -> None:
    pieces = rects_minus_holes((0, 0, 10, 10), [(2, 2, 4, 5), (6, 0, 7, 10)])
    total = sum((r[2] - r[0]) * (r[3] - r[1]) for r in pieces)
    assert total == pytest.approx(100 - 6 - 10)
    for a in range(len(pieces)):
        for b in range(a + 1, len(pieces)):
            p, q = pieces[a], pieces[b]
            assert not (p[0] < q[2] and q[0] < p[2] and p[1] < q[3] and q[1] < p[3])


def test_wall_leaves_the_door_open() -> None:
    mesh = wall(0, 0.0, 10.0, 0.0, 0.2, 0.0, 3.0, [(4.0, 0.0, 5.4, 2.2)])
    volume = sum(c.volume for c in _components(mesh))
    assert volume == pytest.approx(0.2 * (10 * 3 - 1.4 * 2.2))


def test_parts_batches_everything() -> None:
    p = Parts()
    p.box((0, 0, 0), (1, 1, 1))
    p.box_at((5, 5, 5), (1, 2, 1))
    p.cylinder((0, 0, 2), (0, 0, 3), 0.2, 12)
    p.cylinder((1, 0, 2), (1, 0, 3), 0.2, 8)
    p.add(boxes([3, 3, 3], [4, 4, 4]))
    mesh = p.build()
    assert len(mesh.triangles) == 3 * 12 + (4 * 12 - 4) + (4 * 8 - 4)
    assert len(_components(mesh)) == 5
    _assert_closed_outward(mesh)
    assert len(concat([]).triangles) == 0
