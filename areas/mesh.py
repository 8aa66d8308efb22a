"""The triangle mesh the area generators build, and joining meshes into one."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@dataclass
class Mesh:
    """A triangle mesh.

    Attributes:
        vertices: (V, 3) float64 metres.
        triangles: (F, 3) int64 indices into ``vertices``.
    """

    vertices: FloatArray
    triangles: IntArray

    @staticmethod
    def empty() -> Mesh:
        return Mesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))


def concat(meshes: Sequence[Mesh]) -> Mesh:
    """One mesh holding all ``meshes``; vertex indices are shifted, nothing is merged."""
    if not meshes:
        return Mesh.empty()
    offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
    return Mesh(
        np.concatenate([m.vertices for m in meshes]),
        np.concatenate([m.triangles + off for m, off in zip(meshes, offsets, strict=True)]),
    )
