"""Physics world: hover, trajectory tracking and collision detection in a closed 6 x 4 x 2.5 box."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import open3d as o3d
import pytest
from pydantic import ValidationError

from sim import world as world_module
from sim.trajectory import TrajectorySample, plan_trajectory
from sim.vehicle import VehicleLimits
from sim.world import Contact, PhysicsConfig, World, pybullet

FloatArray = npt.NDArray[np.float64]

LIMITS = VehicleLimits()
BOX = (6.0, 4.0, 2.5)
CENTRE = np.array([3.0, 2.0, 1.25])


def box_mesh() -> tuple[FloatArray, npt.NDArray[np.int32]]:
    mesh = o3d.geometry.TriangleMesh.create_box(*BOX)
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.triangles, dtype=np.int32)


def make_world(start: FloatArray, config: PhysicsConfig | None = None) -> World:
    vertices, triangles = box_mesh()
    return World(vertices, triangles, start, LIMITS, config or PhysicsConfig())


def at_rest(position: FloatArray) -> TrajectorySample:
    return TrajectorySample(
        position=np.asarray(position, dtype=np.float64),
        velocity=np.zeros(3),
        acceleration=np.zeros(3),
        yaw=0.0,
        yaw_rate=0.0,
    )


def test_initial_state() -> None:
    with make_world(CENTRE) as world:
        assert world.dt == pytest.approx(0.01)
        assert world.time == 0.0
        assert np.array_equal(world.position, CENTRE)
        assert np.array_equal(world.velocity, np.zeros(3))


def test_hover_at_rest_stays_put_without_contact() -> None:
    with make_world(CENTRE) as world:
        reference = at_rest(CENTRE)
        deviation = 0.0
        for _ in range(500):  # 5 s at 100 Hz
            assert world.step(reference) is None
            deviation = max(deviation, float(np.linalg.norm(world.position - CENTRE)))
        assert world.time == pytest.approx(5.0)
        assert deviation < 0.01  # gravity is compensated: it does not sag
        assert np.linalg.norm(world.velocity) < 0.01


def test_hover_recovers_from_an_offset_start() -> None:
    # The reference is 0.2 m above the start: the PD loop pulls the sphere up and settles.
    with make_world(CENTRE) as world:
        target = CENTRE + np.array([0.0, 0.0, 0.2])
        for _ in range(300):
            assert world.step(at_rest(target)) is None
        assert np.linalg.norm(world.position - target) < 0.005


def test_tracks_a_trajectory_leg() -> None:
    start = np.array([1.5, 2.0, 1.25])
    goal = np.array([4.5, 2.0, 1.25])  # a 3 m leg
    traj = plan_trajectory([*start, 0.0], [[*goal, 0.5]], LIMITS)
    with make_world(start) as world:
        worst = 0.0
        lateral = 0.0
        while world.time < traj.duration + 1.0:
            assert world.step(traj.sample(world.time)) is None
            reference = traj.sample(world.time)
            worst = max(worst, float(np.linalg.norm(world.position - reference.position)))
            lateral = max(lateral, float(np.abs(world.position[1:] - start[1:]).max()))
        assert worst < 0.05
        assert lateral < 1e-3  # stays on the straight segment
        assert np.linalg.norm(world.position - goal) < 0.02
        assert np.linalg.norm(world.velocity) < 0.05
        # It actually flew the leg at speed.
        assert traj.duration < 3.5


def test_commanding_into_a_wall_produces_a_contact() -> None:
    # The sphere (radius 0.3) is sent to 0.1 m from the wall x = 6: its surface must touch.
    assert LIMITS.radius_m == 0.3
    target = np.array([5.9, 2.0, 1.25])
    traj = plan_trajectory([*CENTRE, 0.0], [[*target, 0.0]], LIMITS)
    with make_world(CENTRE) as world:
        contact = None
        while world.time < traj.duration + 2.0 and contact is None:
            contact = world.step(traj.sample(world.time))
        assert isinstance(contact, Contact)
        assert contact.depth > 0.0
        assert contact.depth < 0.05
        assert contact.time == pytest.approx(world.time)
        assert contact.time < traj.duration  # before the reference reaches the target
        # The sphere centre is one radius from the wall (within the penetration).
        assert contact.position[0] == pytest.approx(BOX[0] - LIMITS.radius_m, abs=0.02)
        assert contact.position[1:] == pytest.approx(CENTRE[1:], abs=1e-3)
        assert np.array_equal(contact.position, world.position)
        assert contact.position is not world.position  # a copy, not a live view


def test_flying_close_to_a_wall_is_not_a_contact() -> None:
    # 0.35 m from the wall: 5 cm of clearance for the 0.3 m sphere.
    target = np.array([5.65, 2.0, 1.25])
    traj = plan_trajectory([*CENTRE, 0.0], [[*target, 0.0]], LIMITS)
    with make_world(CENTRE) as world:
        while world.time < traj.duration + 1.0:
            assert world.step(traj.sample(world.time)) is None
        assert world.position[0] == pytest.approx(5.65, abs=0.01)


def test_falling_onto_the_floor_is_a_contact() -> None:
    # Reference 0.1 m above the floor: the sphere touches it.
    start = np.array([3.0, 2.0, 0.6])
    with make_world(start) as world:
        contact = None
        for _ in range(300):
            contact = world.step(at_rest(np.array([3.0, 2.0, 0.1])))
            if contact is not None:
                break
        assert contact is not None
        assert contact.depth > 0.0
        assert contact.position[2] == pytest.approx(LIMITS.radius_m, abs=0.02)


def test_physics_rate() -> None:
    with pytest.raises(ValidationError):
        PhysicsConfig(rate_hz=99.0)
    with pytest.raises(ValidationError):
        PhysicsConfig(rate_hz=50.0)
    assert PhysicsConfig(rate_hz=100.0).rate_hz == 100.0
    with pytest.raises(ValidationError):
        PhysicsConfig(kp=0.0)
    with make_world(CENTRE, PhysicsConfig(rate_hz=250.0)) as world:
        assert world.dt == pytest.approx(0.004)
        for _ in range(250):
            assert world.step(at_rest(CENTRE)) is None
        assert world.time == pytest.approx(1.0)
        assert np.linalg.norm(world.position - CENTRE) < 0.01


def test_close_is_idempotent() -> None:
    world = make_world(CENTRE)
    world.step(at_rest(CENTRE))
    world.close()
    world.close()


def test_contacts_of_a_scene_in_many_parts_match_each_part_asked_alone(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # The box split into six bodies of two triangles; the sphere pushed into a corner touches
    # several at once. Each step's contact is the deepest over the parts, asked one by one.
    monkeypatch.setattr(world_module, "MAX_PART_TRIANGLES", 2)
    corner = np.array([5.85, 3.85, 0.15])
    with make_world(CENTRE) as world:
        assert len(world._scene) == 6
        touched = 0
        for _ in range(400):
            contact = world.step(at_rest(corner))
            depths = [c[8] for part in world._scene
                      for c in pybullet.getContactPoints(world._body, part,
                                                         physicsClientId=world._client)
                      if c[8] <= 0.0]
            if depths:
                touched += 1
                assert contact is not None and contact.depth == -min(depths)
            else:
                assert contact is None
        assert touched > 100


def test_the_control_law_is_numpys_to_the_bit(monkeypatch: pytest.MonkeyPatch) -> None:
    # The step computes the force in plain floats; NumPy's arrays in the same order of
    # operations give the same bits.
    rng = np.random.default_rng(5)
    config = PhysicsConfig()
    forces: list[list[float]] = []
    real = pybullet.applyExternalForce

    def keep(body: int, link: int, force: list[float], *args: object, **kw: object) -> None:
        forces.append(list(force))
        real(body, link, force, *args, **kw)

    monkeypatch.setattr(pybullet, "applyExternalForce", keep)
    with make_world(CENTRE, config) as world:
        for _ in range(50):
            reference = TrajectorySample(
                position=CENTRE + rng.normal(0.0, 0.3, 3), velocity=rng.normal(0.0, 1.0, 3),
                acceleration=rng.normal(0.0, 2.0, 3), yaw=0.0, yaw_rate=0.0)
            p, v = world.position.copy(), world.velocity.copy()
            world.step(reference)
            accel = (reference.acceleration + config.kp * (reference.position - p)
                     + config.kd * (reference.velocity - v))
            expected = LIMITS.mass_kg * (accel + np.array([0.0, 0.0, world_module.GRAVITY]))
            assert forces[-1] == expected.tolist()
