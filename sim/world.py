"""The physical world: the area mesh as a static pybullet body and the vehicle as a rigid sphere.

A position controller (feed-forward acceleration plus PD on position and velocity, gravity
compensated) pushes the sphere along the reference trajectory at the physics rate. Any contact
between the sphere and the scene is a collision. Yaw is not simulated dynamically: a level MAV's
yaw loop is much faster than its translation, so the body takes the reference yaw.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field

from sim.quiet import quiet_native_output

with quiet_native_output():  # pybullet prints its build time on import
    import pybullet

from sim.geometry import FloatArray
from sim.trajectory import TrajectorySample
from sim.vehicle import VehicleLimits

GRAVITY = 9.81


class PhysicsConfig(BaseModel):
    """Physics and control rates and gains."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    rate_hz: float = Field(100.0, ge=100.0, description="physics and control rate")
    kp: float = Field(36.0, gt=0.0, description="1/s², position gain")
    kd: float = Field(12.0, gt=0.0, description="1/s, velocity gain (critical damping)")


@dataclass(frozen=True)
class Contact:
    """A collision: where and when the sphere touched the scene.

    Attributes:
        time: simulated seconds.  position: (3,) sphere centre, m.  depth: penetration, m.
    """

    time: float
    position: FloatArray
    depth: float


# pybullet refuses mesh shapes above 131,072 vertices or 524,288 indices: large scenes are
# split into parts below both, each its own static body.
MAX_PART_TRIANGLES = 40_000


def _scene_shapes(vertices: FloatArray, triangles: npt.NDArray[np.int32], cid: int) -> list[int]:
    verts = np.asarray(vertices, dtype=np.float64)
    tris = np.asarray(triangles, dtype=np.int32).reshape(-1, 3)
    shapes = []
    for start in range(0, max(len(tris), 1), MAX_PART_TRIANGLES):
        part = tris[start:start + MAX_PART_TRIANGLES]
        used, local = np.unique(part, return_inverse=True)
        shapes.append(pybullet.createCollisionShape(
            pybullet.GEOM_MESH,
            vertices=verts[used].tolist(),
            indices=local.astype(np.int32).reshape(-1).tolist(),
            flags=pybullet.GEOM_FORCE_CONCAVE_TRIMESH,
            physicsClientId=cid,
        ))
    return shapes


class World:
    """One pybullet DIRECT client holding the scene and the vehicle."""

    def __init__(
        self,
        vertices: FloatArray,
        triangles: npt.NDArray[np.int32],
        start_position: FloatArray,
        limits: VehicleLimits,
        config: PhysicsConfig | None = None,
    ) -> None:
        self.config = config or PhysicsConfig()
        self.limits = limits
        self.dt = 1.0 / self.config.rate_hz
        self._client = pybullet.connect(pybullet.DIRECT)
        cid = self._client
        pybullet.setGravity(0.0, 0.0, -GRAVITY, physicsClientId=cid)
        pybullet.setPhysicsEngineParameter(
            fixedTimeStep=self.dt, numSubSteps=1, physicsClientId=cid
        )
        # The scene's bodies, a set: contacts are told apart from other bodies by membership.
        self._scene = frozenset(
            pybullet.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=shape,
                                     physicsClientId=cid)
            for shape in _scene_shapes(vertices, triangles, cid)
        )
        sphere = pybullet.createCollisionShape(
            pybullet.GEOM_SPHERE, radius=limits.radius_m, physicsClientId=cid
        )
        self._body = pybullet.createMultiBody(
            baseMass=limits.mass_kg,
            baseCollisionShapeIndex=sphere,
            basePosition=np.asarray(start_position, dtype=np.float64).tolist(),
            physicsClientId=cid,
        )
        pybullet.changeDynamics(
            self._body, -1, linearDamping=0.0, angularDamping=0.0, physicsClientId=cid
        )
        self.time = 0.0
        self.position = np.asarray(start_position, dtype=np.float64).copy()
        self.velocity = np.zeros(3)

    def step(self, reference: TrajectorySample) -> Contact | None:
        """Advance one physics step tracking `reference`; the contact if the sphere touched."""
        cfg, cid = self.config, self._client
        # Plain floats in NumPy's order of operations, which give the same IEEE results: the
        # step runs 100 times a simulated second, and operations on 3-element arrays cost
        # more than the arithmetic.
        mass, kp, kd = self.limits.mass_kg, cfg.kp, cfg.kd
        position = self.position.tolist()
        velocity = self.velocity.tolist()
        force = [
            mass * ((a + kp * (r - p)) + kd * (w - v) + g)
            for a, r, p, w, v, g in zip(
                reference.acceleration.tolist(), reference.position.tolist(), position,
                reference.velocity.tolist(), velocity, (0.0, 0.0, GRAVITY), strict=True)
        ]
        pybullet.applyExternalForce(
            self._body, -1, force, position, pybullet.WORLD_FRAME, physicsClientId=cid,
        )
        pybullet.stepSimulation(physicsClientId=cid)
        self.time += self.dt
        pos, _ = pybullet.getBasePositionAndOrientation(self._body, physicsClientId=cid)
        vel, _ = pybullet.getBaseVelocity(self._body, physicsClientId=cid)
        self.position = np.array(pos)
        self.velocity = np.array(vel)
        # One query for the sphere's contacts with every scene part (a large scene has many
        # parts); the deepest is the same whichever order they come in.
        touching = [c[8] for c in pybullet.getContactPoints(self._body, physicsClientId=cid)
                    if c[8] <= 0.0 and (c[2] if c[1] == self._body else c[1]) in self._scene]
        if not touching:
            return None
        return Contact(self.time, self.position.copy(), float(-min(touching)))

    def close(self) -> None:
        if self._client >= 0:
            pybullet.disconnect(physicsClientId=self._client)
            self._client = -1

    def __enter__(self) -> World:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
