"""The ground truth's dense surface cloud, held as its cache file stores it.

The large areas hold tens of millions of 2 cm samples (18 M on WAREHOUSE: 205 MiB as float32).
A run scores against two fixed subsamples of them, so the cloud stays packed as uint16 steps
(6 bytes a point) and only the rows asked for are decoded; the whole float32 cloud exists only
while a caller that asked for it (`SurfaceCloud.points`) holds it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

Float32Array = npt.NDArray[np.float32]

# Largest step of the stored point coordinates: clouds up to 65 m a side are stored as uint16
# steps (a rounding error of at most 0.5 mm, against a 2 cm sample spacing and 5 cm metrics).
QUANTUM = 1e-3
# Truth points are subsampled with one fixed seed, never a run's: every run of an area is scored
# against the same points, whatever its seed.
TRUTH_SAMPLE_SEED = 0
# Rows decoded at a time: decoding all at once makes two float64 copies of the cloud.
DECODE_ROWS = 1 << 20


@dataclass(frozen=True, eq=False)
class SurfaceCloud:
    """(N, 3) surface samples in the grid frame, metres: either packed or plain float32.

    Attributes:
        codes: (N, 3) uint16 steps from ``origin``, or None when the cloud is stored plain.
        origin: (3,) float64 corner the codes count from, metres.
        step: (3,) float64 size of one code step per axis, metres (at most ``QUANTUM``).
        plain: (N, 3) float32 points, when the cloud is too wide for uint16 steps of
            ``QUANTUM`` or has not been packed (a freshly computed ground truth).
    """

    codes: npt.NDArray[np.uint16] | None = None
    origin: npt.NDArray[np.float64] | None = None
    step: npt.NDArray[np.float64] | None = None
    plain: Float32Array | None = None

    @classmethod
    def of(cls, points: npt.ArrayLike) -> SurfaceCloud:
        """The points as they are (float32), unpacked."""
        return cls(plain=np.asarray(points, dtype=np.float32).reshape(-1, 3))

    def packed(self) -> SurfaceCloud:
        """The cloud as the cache file stores it: uint16 steps of at most ``QUANTUM`` from its
        minimum corner, or plain float32 when it is too wide for that."""
        if self.codes is not None or self.plain is None or len(self.plain) == 0:
            return self
        lo = self.plain.min(axis=0).astype(np.float64)
        step = np.maximum((self.plain.max(axis=0) - lo) / 65535.0, 1e-9)
        if np.any(step > QUANTUM):
            return self
        codes = np.empty(self.plain.shape, dtype=np.uint16)
        for start in range(0, len(codes), DECODE_ROWS):
            rows = slice(start, start + DECODE_ROWS)
            codes[rows] = np.rint((self.plain[rows] - lo) / step)
        return SurfaceCloud(codes=codes, origin=lo, step=step)

    @classmethod
    def from_arrays(cls, data: Mapping[str, Any]) -> SurfaceCloud:
        """The cloud from the arrays `arrays` wrote (an open ``.npz`` file, say)."""
        if "surface_codes" in data:
            return cls(codes=np.asarray(data["surface_codes"], dtype=np.uint16),
                       origin=np.asarray(data["surface_origin"], dtype=np.float64),
                       step=np.asarray(data["surface_step"], dtype=np.float64))
        return cls.of(data["surface_points"])

    def arrays(self) -> dict[str, npt.NDArray[Any]]:
        """Named arrays to store the cloud as it is held."""
        if self.codes is not None:
            assert self.origin is not None and self.step is not None
            return {"surface_codes": self.codes, "surface_origin": self.origin,
                    "surface_step": self.step}
        assert self.plain is not None
        return {"surface_points": self.plain}

    def __len__(self) -> int:
        held = self.codes if self.codes is not None else self.plain
        return 0 if held is None else len(held)

    @property
    def nbytes(self) -> int:
        """Bytes the cloud holds resident."""
        held = self.codes if self.codes is not None else self.plain
        return 0 if held is None else int(held.nbytes)

    def take(self, rows: npt.NDArray[np.intp] | slice) -> Float32Array:
        """(k, 3) float32 points of the given rows, decoded."""
        if self.codes is None:
            assert self.plain is not None
            return self.plain[rows]
        assert self.origin is not None and self.step is not None
        return (self.codes[rows] * self.step + self.origin).astype(np.float32)

    def points(self) -> Float32Array:
        """(N, 3) float32: the whole cloud, decoded afresh on each call (hold the result)."""
        if self.codes is None:
            return np.zeros((0, 3), np.float32) if self.plain is None else self.plain
        out = np.empty(self.codes.shape, dtype=np.float32)
        for start in range(0, len(out), DECODE_ROWS):
            rows = slice(start, start + DECODE_ROWS)
            out[rows] = self.take(rows)
        return out

    def sample(self, count: int) -> Float32Array:
        """At most ``count`` points, the same ones on every call and for every run, in their
        stored order (all of them when the cloud has no more)."""
        n = len(self)
        if n <= count:
            return self.points()
        rng = np.random.default_rng(TRUTH_SAMPLE_SEED)
        return self.take(np.sort(rng.choice(n, size=count, replace=False)))
