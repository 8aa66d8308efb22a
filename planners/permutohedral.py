"""Gaussian filtering of scattered points on the permutohedral lattice (Adams, Baek, Davis,
"Fast high-dimensional filtering using the permutohedral lattice", Eurographics 2010).

The filter approximates, for query features q_j and splatted features f_i with values v_i,

    out_j = sum_i v_i exp(-|f_i - q_j|² / 2)

in time linear in the number of points (features are scaled beforehand so that the wanted
Gaussian has unit standard deviation in every dimension). Three steps:

- **splat**: each point is lifted onto the hyperplane sum(x) = 0 of R^(d+1) and its value is
  shared among the d+1 vertices of the lattice simplex that encloses it, by barycentric
  weights; the vertices live in a hash table keyed by their integer coordinates.
- **blur**: along each of the d+1 lattice directions, every vertex takes the [1 2 1] / 4
  average of itself and its two neighbours (vertices missing from the table count as zero).
- **slice**: any query point, splatted or not, reads the blurred values of its own enclosing
  simplex's vertices with its barycentric weights.

A homogeneous channel (each point's weight 1) travels with the values: sliced, it is the
Gaussian density of the points at the query, and dividing by it gives the normalised
(bilateral) filter. The lattice's Gaussian is an approximation: its absolute scale differs
from the exact sum by a roughly constant factor (`density_scale` corrects most of it) and its
shape is slightly anisotropic; see tests/planners/test_permutohedral.py for measured errors.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

_EMPTY = -1


def _elevation_matrix(d: int) -> FloatArray:
    """(d+1, d) map from R^d onto the hyperplane sum(x) = 0 of R^(d+1), scaled so that the
    lattice blur (three [1 2 1] passes per direction would be exact for a Gaussian of variance
    ~ 2/3 (d+1)² per axis) matches a unit-variance Gaussian of the features: Adams et al. 2010,
    section 3.1, with orthonormal basis columns times sqrt(2/3) (d+1)."""
    e = np.zeros((d + 1, d))
    for j in range(1, d + 1):
        e[:j, j - 1] = 1.0
        e[j, j - 1] = -float(j)
        e[:, j - 1] /= math.sqrt(j * (j + 1))
    return e * (math.sqrt(2.0 / 3.0) * (d + 1))


@numba.njit(cache=True)
def _simplex(
    x: FloatArray, rem0: IntArray, rank: IntArray, bary: FloatArray
) -> None:
    """Enclosing simplex of one elevated point x ((d+1,)): fills the nearest remainder-0
    lattice point rem0, the rank of each coordinate's offset from it (0 = largest) and the
    barycentric weights bary ((d+2,), first d+1 used)."""
    dp1 = x.shape[0]
    d = dp1 - 1
    total = 0
    for i in range(dp1):
        v = x[i] / dp1
        up = math.ceil(v) * dp1
        down = math.floor(v) * dp1
        rem0[i] = up if up - x[i] < x[i] - down else down
        total += rem0[i]
    total //= dp1
    for i in range(dp1):
        rank[i] = 0
    for i in range(d):
        for j in range(i + 1, dp1):
            if x[i] - rem0[i] < x[j] - rem0[j]:
                rank[i] += 1
            else:
                rank[j] += 1
    # rem0 must lie on the hyperplane: move the coordinates with the smallest (sum > 0) or
    # largest (sum < 0) offsets by one lattice step, re-ranking accordingly.
    if total > 0:
        for i in range(dp1):
            if rank[i] >= dp1 - total:
                rem0[i] -= dp1
                rank[i] += total - dp1
            else:
                rank[i] += total
    elif total < 0:
        for i in range(dp1):
            if rank[i] < -total:
                rem0[i] += dp1
                rank[i] += dp1 + total
            else:
                rank[i] += total
    for i in range(d + 2):
        bary[i] = 0.0
    for i in range(dp1):
        delta = (x[i] - rem0[i]) / dp1
        bary[d - rank[i]] += delta
        bary[d + 1 - rank[i]] -= delta
    bary[0] += 1.0 + bary[d + 1]


@numba.njit(cache=True)
def _fingerprint(key: npt.NDArray[np.int32]) -> np.int64:
    """64-bit hash of a key: FNV-style combination of the coordinates, then a finaliser so that
    the low bits (the slot) depend on every bit of every coordinate (lattice keys are highly
    regular: all coordinates of a vertex share their remainder mod d+1)."""
    h = np.uint64(1469598103934665603)
    for i in range(key.shape[0]):
        h = (h ^ np.uint64(np.int64(key[i]) & 0xFFFFFFFF)) * np.uint64(1099511628211)
    h = h ^ (h >> np.uint64(33))
    h = h * np.uint64(0xFF51AFD7ED558CCD)
    h = h ^ (h >> np.uint64(33))
    return np.int64(h)


# The hash table: (capacity, 2) int64 rows of (fingerprint, vertex index or -1). Keys are
# matched by their 64-bit fingerprints alone, so that a look-up touches one row (one cache
# line) instead of also reading the stored key: two of M distinct keys share a fingerprint
# with probability about M² / 2^65, below 1e-10 for a million vertices.


@numba.njit(cache=True)
def _find(table: IntArray, h: np.int64) -> int:
    """Index of the vertex whose fingerprint is h, or -1."""
    mask = table.shape[0] - 1
    slot = h & mask
    while True:
        idx = table[slot, 1]
        if idx == _EMPTY:
            return -1
        if table[slot, 0] == h:
            return idx
        slot = (slot + 1) & mask


@numba.njit(cache=True)
def _insert(keys: npt.NDArray[np.int32], table: IntArray, count: int,
            key: npt.NDArray[np.int32]) -> tuple[int, int]:
    """Index of `key`, stored if new; returns (index, new count)."""
    h = _fingerprint(key)
    mask = table.shape[0] - 1
    slot = h & mask
    while True:
        idx = table[slot, 1]
        if idx == _EMPTY:
            table[slot, 0] = h
            table[slot, 1] = count
            for i in range(key.shape[0]):
                keys[count, i] = key[i]
            return count, count + 1
        if table[slot, 0] == h:
            return idx, count
        slot = (slot + 1) & mask


@numba.njit(cache=True)
def _new_table(capacity: int) -> IntArray:
    table = np.empty((capacity, 2), dtype=np.int64)
    table[:, 1] = _EMPTY
    return table


@numba.njit(cache=True)
def _rehash(table: IntArray, capacity: int) -> IntArray:
    """The same entries in a table of `capacity` slots."""
    out = _new_table(capacity)
    mask = capacity - 1
    for r in range(table.shape[0]):
        if table[r, 1] == _EMPTY:
            continue
        slot = table[r, 0] & mask
        while out[slot, 1] != _EMPTY:
            slot = (slot + 1) & mask
        out[slot, 0] = table[r, 0]
        out[slot, 1] = table[r, 1]
    return out


@numba.njit(cache=True)
def _splat_into(elevated: FloatArray, values: FloatArray, keys: npt.NDArray[np.int32],
                table: IntArray, acc: FloatArray, count: int) -> tuple[IntArray, int]:
    """Splat (N, d+1) elevated points with (N, C) values into the lattice: new vertices are
    appended to keys (rows count..) and acc, which must have room for (d+1) N more. Returns
    the hash table (grown to stay at most half full) and the new vertex count."""
    n, dp1 = elevated.shape
    d = dp1 - 1
    c = values.shape[1]
    rem0 = np.empty(dp1, dtype=np.int64)
    rank = np.empty(dp1, dtype=np.int64)
    bary = np.empty(d + 2, dtype=np.float64)
    key = np.empty(d, dtype=np.int32)
    for p in range(n):
        # A small table stays in cache; keep it at most half full.
        if 2 * (count + dp1) > table.shape[0]:
            table = _rehash(table, 2 * table.shape[0])
        _simplex(elevated[p], rem0, rank, bary)
        for k in range(dp1):
            # Vertex k of the simplex: rem0 plus the canonical offset for the remainder k.
            for i in range(d):
                if rank[i] <= d - k:
                    key[i] = rem0[i] + k
                else:
                    key[i] = rem0[i] + k - dp1
            idx, count = _insert(keys, table, count, key)
            w = bary[k]
            for ch in range(c):
                acc[idx, ch] += w * values[p, ch]
    return table, count


@numba.njit(cache=True)
def _link(keys: npt.NDArray[np.int32], table: IntArray, nb: npt.NDArray[np.int32],
          start: int, count: int) -> None:
    """Fill nb[j, 0 or 1, v], the lower and upper neighbour along each lattice direction j
    (-1 if absent), for the new vertices start..count-1 and, symmetrically, for the vertices
    they neighbour (u is v's lower neighbour exactly when v is u's upper one)."""
    d = keys.shape[1]
    lower = np.empty(d, dtype=np.int32)
    upper = np.empty(d, dtype=np.int32)
    for v in range(start, count):
        for j in range(d + 1):
            # Along direction j: key -/+ ((1, .., 1) - (d+1) e_j) (the (d+1)-th coordinate is
            # implied by the zero sum, so direction d moves only the others).
            for i in range(d):
                lower[i] = keys[v, i] - 1
                upper[i] = keys[v, i] + 1
            if j < d:
                lower[j] = keys[v, j] + d
                upper[j] = keys[v, j] - d
            u = _find(table, _fingerprint(lower))
            if u >= 0:
                nb[j, 0, v] = u
                nb[j, 1, u] = v
            w = _find(table, _fingerprint(upper))
            if w >= 0:
                nb[j, 1, v] = w
                nb[j, 0, w] = v


@numba.njit(cache=True)
def _blur(nb: npt.NDArray[np.int32], vals: FloatArray, count: int) -> FloatArray:
    """[1 2 1] / 4 along each of the d+1 lattice directions; returns the new (M, C) values
    (vertices missing from the lattice count as zero, as do vertices of zero mass)."""
    c = vals.shape[1]
    cur = vals[:count].copy()
    nxt = np.empty_like(cur)
    for j in range(nb.shape[0]):
        for v in range(count):
            a = nb[j, 0, v]
            b = nb[j, 1, v]
            for ch in range(c):
                s = 0.5 * cur[v, ch]
                if a >= 0:
                    s += 0.25 * cur[a, ch]
                if b >= 0:
                    s += 0.25 * cur[b, ch]
                nxt[v, ch] = s
        cur, nxt = nxt, cur
    return cur


@numba.njit(cache=True)
def _slice(elevated: FloatArray, table: IntArray, vals: FloatArray) -> FloatArray:
    """(Q, C) barycentric interpolation of vertex values at (Q, d+1) elevated queries."""
    q, dp1 = elevated.shape
    d = dp1 - 1
    c = vals.shape[1]
    out = np.zeros((q, c), dtype=np.float64)
    rem0 = np.empty(dp1, dtype=np.int64)
    rank = np.empty(dp1, dtype=np.int64)
    bary = np.empty(d + 2, dtype=np.float64)
    key = np.empty(d, dtype=np.int32)
    for p in range(q):
        _simplex(elevated[p], rem0, rank, bary)
        for k in range(dp1):
            for i in range(d):
                if rank[i] <= d - k:
                    key[i] = rem0[i] + k
                else:
                    key[i] = rem0[i] + k - dp1
            idx = _find(table, _fingerprint(key))
            if idx < 0:
                continue
            w = bary[k]
            for ch in range(c):
                out[p, ch] += w * vals[idx, ch]
    return out


class PermutohedralLattice:
    """A Gaussian filter of N scattered points in d dimensions, linear in N.

    Build it from the points, `add` more (or remove some, with negative weights) at any time,
    then `density` / `filter` at any queries (the blur runs lazily, once after each change).
    Features must be pre-scaled: the filter's Gaussian is exp(-|f - q|² / 2), so divide each
    dimension by its standard deviation first.

    Args:
        features: (N, d) float point features, d >= 1.
        values: (N, C) or (N,) float values to filter, or None for density only (C = 0).
        weights: (N,) float weight of each point (1 if None); the density channel sums them.

    Attributes:
        d: feature dimension.
        n_channels: C.
        n_vertices: lattice vertices stored (at most (d+1) times the points ever added): the
            size of the hash table and the blur's work.
        density_scale: factor turning the lattice's density into the exact Gaussian sum's
            scale (exact where the points' density is locally constant, see `_density_scale`).
    """

    def __init__(self, features: npt.ArrayLike, values: npt.ArrayLike | None = None,
                 weights: npt.ArrayLike | None = None) -> None:
        f = self._check_features(features, None)
        self.d = f.shape[1]
        v = None if values is None else np.asarray(values)
        self.n_channels = 0 if v is None else (1 if v.ndim == 1 else int(v.shape[-1]))
        self._elevation = _elevation_matrix(self.d)
        self.density_scale = _density_scale(self.d)
        self.n_vertices = 0
        self._keys = np.empty((0, self.d), dtype=np.int32)
        self._acc = np.zeros((0, self.n_channels + 1))
        self._nb = np.full((self.d + 1, 2, 0), -1, dtype=np.int32)
        self._table = _new_table(1 << max(4, int(4 * len(f)).bit_length()))
        self._blurred: FloatArray | None = None
        self.add(f, values, weights)

    def _check_features(self, features: npt.ArrayLike, d: int | None) -> FloatArray:
        f = np.asarray(features, dtype=np.float64)
        if f.ndim != 2 or f.shape[1] < 1 or (d is not None and f.shape[1] != d):
            want = "(N, d) with d >= 1" if d is None else f"(N, {d})"
            raise ValueError(f"features must be {want}, got {f.shape}")
        if not np.all(np.isfinite(f)):
            raise ValueError("features must be finite")
        return f

    def add(self, features: npt.ArrayLike, values: npt.ArrayLike | None = None,
            weights: npt.ArrayLike | None = None) -> None:
        """Splat (N, d) more points with (N, C) values and (N,) weights (1 if None); a point
        added before is removed by adding it again with the opposite weight. Its vertices stay,
        with no mass: they still carry the blur, exactly as for a point of weight 0 (a rebuild
        without the point drops them, and truncates the blur a little more)."""
        f = self._check_features(features, self.d)
        n = len(f)
        w = np.ones(n) if weights is None else np.asarray(weights, dtype=np.float64)
        if w.shape != (n,):
            raise ValueError(f"weights must be ({n},), got {w.shape}")
        if values is None:
            v = np.zeros((n, 0))
        else:
            v = np.asarray(values, dtype=np.float64)
            if v.ndim == 1:
                v = v[:, None]
            if v.shape[0] != n:
                raise ValueError(f"values must have {n} rows, got {v.shape}")
        if v.shape[1] != self.n_channels:
            raise ValueError(f"values must have {self.n_channels} channels, got {v.shape[1]}")
        if n == 0:
            return
        homogeneous = np.empty((n, self.n_channels + 1))
        homogeneous[:, :-1] = v * w[:, None]
        homogeneous[:, -1] = w
        self._reserve(self.n_vertices + n * (self.d + 1))
        start = self.n_vertices
        self._table, count = _splat_into(self._elevate(f), homogeneous, self._keys, self._table,
                                         self._acc, start)
        _link(self._keys, self._table, self._nb, start, count)
        self.n_vertices = int(count)
        self._blurred = None

    def _reserve(self, rows: int) -> None:
        """Room for `rows` vertices in the key, value and neighbour arrays."""
        have = len(self._keys)
        if rows <= have:
            return
        size = max(rows, 2 * have)
        keys = np.empty((size, self.d), dtype=np.int32)
        keys[:have] = self._keys
        acc = np.zeros((size, self.n_channels + 1))
        acc[:have] = self._acc
        nb = np.full((self.d + 1, 2, size), -1, dtype=np.int32)
        nb[:, :, :have] = self._nb
        self._keys, self._acc, self._nb = keys, acc, nb

    def _elevate(self, points: FloatArray) -> FloatArray:
        return np.ascontiguousarray(points @ self._elevation.T)

    def slice_raw(self, queries: npt.ArrayLike) -> FloatArray:
        """(Q, C+1) blurred lattice values at (Q, d) queries: the filtered values times the
        density, then the density itself (lattice scale)."""
        q = np.asarray(queries, dtype=np.float64)
        if q.ndim != 2 or q.shape[1] != self.d:
            raise ValueError(f"queries must be (Q, {self.d}), got {q.shape}")
        if len(q) == 0 or self.n_vertices == 0:
            return np.zeros((len(q), self.n_channels + 1))
        if self._blurred is None:
            self._blurred = _blur(self._nb, self._acc, self.n_vertices)
        return _slice(self._elevate(q), self._table, self._blurred)

    def density(self, queries: npt.ArrayLike) -> FloatArray:
        """(Q,) approximate sum_i w_i exp(-|f_i - q|² / 2) at (Q, d) queries."""
        return self.slice_raw(queries)[:, -1] * self.density_scale

    def filter(self, queries: npt.ArrayLike, eps: float = 1e-12) -> FloatArray:
        """(Q, C) normalised filter at (Q, d) queries: sum_i w_i v_i g_i / sum_i w_i g_i
        (0 where the density is below `eps`)."""
        raw = self.slice_raw(queries)
        dens = raw[:, -1:]
        out = np.zeros_like(raw[:, :-1])
        ok = dens[:, 0] > eps
        out[ok] = raw[ok, :-1] / dens[ok]
        return out


def _density_scale(d: int) -> float:
    """Ratio of the exact Gaussian sum to the lattice density in a region of constant point
    density rho: splat and blur conserve mass, so a vertex holds rho times the feature volume
    of its lattice cell, (d+1)^(d-1/2) / s^d with s = sqrt(2/3) (d+1) the elevation scale,
    while the exact sum is rho (2 pi)^(d/2). Hence (4 pi / 3)^(d/2) sqrt(d+1)."""
    return float((4.0 * math.pi / 3.0) ** (d / 2.0) * math.sqrt(d + 1.0))
