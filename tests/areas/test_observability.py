"""Reachable and observable free space: the clearance rule against brute force, doors the vehicle
can and cannot pass, the camera's elevation band, and the defaults against the simulator's."""

from __future__ import annotations

import itertools
import math

import numpy as np
import numpy.typing as npt
import pytest

from areas.observability import ViewModel, band_directions, observability, traversable

BoolArray = npt.NDArray[np.bool_]


def _brute_traversable(blocked: BoolArray, vs: float, radius: float) -> BoolArray:
    """Every free centre against every blocked cube and every cube outside the grid."""
    shape = np.array(blocked.shape)
    margin = math.ceil(radius / vs) + 1
    padded = np.pad(blocked, margin, constant_values=True)
    cubes = np.argwhere(padded) - margin  # indices in the unpadded grid
    out = np.zeros_like(blocked)
    for ijk in itertools.product(*(range(n) for n in shape)):
        if blocked[ijk]:
            continue
        d = np.maximum(np.abs(cubes - np.array(ijk)) - 0.5, 0.0) * vs
        out[ijk] = np.min(np.sum(d * d, axis=1)) >= radius**2 - 1e-9
    return out


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("vs", [0.1, 0.2])
def test_traversable_matches_brute_force_on_random_maps(seed: int, vs: float) -> None:
    rng = np.random.default_rng(seed)
    shape, density = ((14, 12, 10), 0.01) if vs == 0.2 else ((20, 18, 16), 0.001)
    blocked = rng.random(shape) < density
    got = traversable(blocked, vs, 0.45)
    np.testing.assert_array_equal(got, _brute_traversable(blocked, vs, 0.45))
    assert got.any() and not got.all()


def _two_rooms(door_m: float, vs: float = 0.1) -> tuple[BoolArray, tuple[int, int, int]]:
    """Two 4 x 4 x 2.4 m rooms side by side along x, a 0.2 m wall between them with a door
    ``door_m`` wide and 2 m high; the start in the middle of the first room."""
    nx, ny, nz = round(8.2 / vs) + 2, round(4.0 / vs) + 2, round(2.4 / vs) + 2
    blocked = np.zeros((nx, ny, nz), dtype=bool)
    blocked[[0, -1], :, :] = True
    blocked[:, [0, -1], :] = True
    blocked[:, :, [0, -1]] = True
    wall = slice(1 + round(4.0 / vs), 1 + round(4.2 / vs))
    blocked[wall, :, :] = True
    half = round(door_m / vs / 2)
    mid = ny // 2
    blocked[wall, mid - half: mid + half, 1: 1 + round(2.0 / vs)] = False
    start = (round(2.0 / vs), mid, round(1.2 / vs))
    return blocked, start


def test_a_door_wide_enough_lets_the_vehicle_through() -> None:
    blocked, start = _two_rooms(1.0)
    seen = observability(blocked, start, 0.1)
    far_room = seen.free_component[round(4.3 / 0.1):, :, :]
    assert seen.reachable[round(6.0 / 0.1), start[1], start[2]]
    # Everything free in the far room is seen (its corners from within it).
    assert np.array_equal(seen.observable_free[round(4.3 / 0.1):], far_room)


def test_a_door_narrower_than_the_vehicle_keeps_the_far_room_out_of_reach() -> None:
    blocked, start = _two_rooms(0.6)
    seen = observability(blocked, start, 0.1)
    beyond = slice(round(4.3 / 0.1), None)
    assert seen.free_component[beyond].any()
    assert not seen.reachable[beyond].any()
    # Through the door the camera sees most of the far room from the near side, but not the
    # corners right behind the wall.
    visible = np.count_nonzero(seen.observable_free[beyond])
    assert 0 < visible < np.count_nonzero(seen.free_component[beyond])
    for y in (2, -3):
        corner = (round(4.35 / 0.1), y, start[2])
        assert seen.free_component[corner] and not seen.observable_free[corner]


def test_the_camera_band_hides_what_lies_straight_below() -> None:
    """A deep, narrow shaft under a room: the vehicle cannot enter it, and a level camera with
    a 36.85 degree half field of view sees only its top, not its floor."""
    vs = 0.1
    blocked = np.ones((60, 60, 80), dtype=bool)
    blocked[1:-1, 1:-1, 40:-1] = False  # the room, 5.8 x 5.8 x 3.9 m
    blocked[28:32, 28:32, 1:40] = False  # the shaft, 0.4 x 0.4 x 3.9 m, opening in its floor
    seen = observability(blocked, (30, 30, 60), vs)
    shaft = seen.free_component[28:32, 28:32, 1:40]
    assert shaft.all() and not seen.reachable[28:32, 28:32, 1:40].any()
    assert seen.observable_free[28:32, 28:32, 38].any()
    assert not seen.observable_free[28:32, 28:32, 1:10].any()


def test_band_directions_are_unit_and_within_the_band() -> None:
    d = band_directions(500, 36.85)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    assert np.max(np.abs(d[:, 2])) <= math.sin(math.radians(36.85))
    # Spread over every azimuth: each 30 degree sector holds some.
    sectors = np.floor(np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 360 / 30)
    assert set(sectors.astype(int)) == set(range(12))


def test_the_view_model_is_the_benchmark_vehicle_and_camera() -> None:
    from sim.config import EpisodeConfig

    config = EpisodeConfig()
    view = ViewModel()
    assert view.safety_radius_m == pytest.approx(config.safety_radius_m)
    assert view.range_m == pytest.approx(config.camera.max_range_m)
    assert 2 * view.vertical_half_fov_deg == pytest.approx(config.camera.fov_v_deg)
