"""Incremental Alg. 1: ρ, Σo and Σ|o|² kept on a dense lattice box, updated by changed voxels.

The three neighbourhood sums of a lattice cell p are linear in the occupancy of the cells within
r_s of p, so adding (removing) a voxel q adds (subtracts) [1, q − p, |q − p|²] at every cell
p = q − o of its ball stencil. Each plan therefore only touches the K stencil cells of the
voxels P* gained or lost since the last plan (a few thousand per edge tick) instead of
recomputing all N·K sums; reading ρ and σ² for P* is then one gather per sum. The sums are
small integers, so the result equals `lattice_frontiers` exactly and does not depend on the
order of updates (tests/test_edge_frontier_cache.py).
"""

from __future__ import annotations

import numpy as np

from services.common.arrays import column_extremes
from services.common.voxels import unpack, z_of
from services.edge_server.ball_sums import MAX_K, pack_fields, unpack_fields
from services.edge_server.frontiers3d import PointFrontiers, ball_offsets, full_ball_variance

CHUNK_VOX = 32  # the box grows in steps of this many voxels per axis (few reallocations)
CHUNK_Z_VOX = 8  # ... and up: a map's height is set by its first frames
GROW_FRACTION = 4  # ... and a side that grows, by at least this fraction of the box
# voxels from which ρ and σ² are read in one compiled pass (compiled_stats.py): numba's import
# costs ~0.5 CPU-s once, the numpy path ~0.1 ms per thousand voxels a plan
COMPILED_FROM = 20_000


class LatticeStats:
    """Dense per-cell neighbourhood sums (ρ, Σo, Σ|o|², packed) over a growing box."""

    def __init__(self, radius_vox: float, z_cap: int | None = None) -> None:
        """`z_cap`: the highest lattice z of a cell that will be read (None: no limit); cells
        above are not kept, nor voxels whose ball cannot reach a kept cell."""
        self.offsets = ball_offsets(radius_vox)
        if len(self.offsets) > MAX_K:
            raise ValueError("r_s > 3 voxels overflows the packed sums (FIELD_BITS)")
        self.pad = int(np.abs(self.offsets).max())
        self.z_cap = z_cap
        self.lo = np.zeros(3, np.int64)
        self.dims = np.zeros(3, np.int64)
        self.sums = np.zeros(0, np.int64)
        # per offset o, the contribution of a voxel at p + o to cell p: [1, o, |o|²]
        self._packed = pack_fields(np.concatenate(
            [np.ones((len(self.offsets), 1), np.int64), self.offsets,
             (self.offsets**2).sum(1, keepdims=True)], 1))

    def _strides(self) -> np.ndarray:
        return np.array([self.dims[1] * self.dims[2], self.dims[2], 1], np.int64)

    def _flat(self, idx: np.ndarray) -> np.ndarray:
        """Box offsets of voxels `idx` (M, 3); by columns: an int64 matmul is 8× slower."""
        s0, s1, _ = self._strides()
        lo = self.lo
        return (idx[:, 0] - lo[0]) * s0 + (idx[:, 1] - lo[1]) * s1 + (idx[:, 2] - lo[2])

    def _fit(self, idx: np.ndarray) -> None:
        """Grow the box (snapped to CHUNK_VOX, with a margin) so every stencil cell of `idx`
        lies inside."""
        idx_lo, idx_hi = column_extremes(idx)
        lo = idx_lo - self.pad
        hi = idx_hi + self.pad + 1
        if self.z_cap is not None:
            hi[2] = min(hi[2], self.z_cap + 1)
        if self.sums.size and (lo >= self.lo).all() and (hi <= self.lo + self.dims).all():
            return
        if self.sums.size:
            old_hi = self.lo + self.dims
            # a side that must grow grows by a quarter of the box too: each growth copies the
            # whole box (a warehouse's is 10⁷-10⁸ cells), so it must happen a few times only
            margin = np.maximum(self.dims // GROW_FRACTION, CHUNK_VOX)
            lo = np.where(lo < self.lo, lo - margin, self.lo)
            hi = np.where(hi > old_hi, hi + margin, old_hi)
        chunk = np.array([CHUNK_VOX, CHUNK_VOX, CHUNK_Z_VOX])
        new_lo = np.floor_divide(lo, chunk) * chunk
        new_hi = new_lo - np.floor_divide(-(hi - new_lo), chunk) * chunk
        if self.z_cap is not None:
            new_hi[2] = min(new_hi[2], self.z_cap + 1)
        new_dims = new_hi - new_lo
        grown = np.zeros(new_dims, np.int64)
        if self.sums.size:
            a = self.lo - new_lo
            b = a + self.dims
            grown[a[0]:b[0], a[1]:b[1], a[2]:b[2]] = self.sums.reshape(*self.dims)
        self.lo, self.dims = new_lo, new_dims
        self.sums = grown.ravel()

    def apply(self, idx: np.ndarray, sign: int) -> None:
        """Add (sign +1) or remove (−1) unique voxels `idx` (M, 3) from the occupancy."""
        if self.z_cap is not None:
            idx = idx[idx[:, 2] <= self.z_cap + self.pad]  # the rest reach no kept cell
        if idx.shape[0] == 0:
            return
        self._fit(idx)
        flat = self._flat(idx)
        off_flat = self.offsets @ self._strides()
        # voxels within `pad` of the cap reach cells above it, which the box does not hold
        band = (idx[:, 2] > self.z_cap - self.pad if self.z_cap is not None
                else np.zeros(idx.shape[0], bool))
        band_flat, band_z = flat[band], idx[band, 2]
        flat = flat[~band]
        for k in range(len(self.offsets)):
            # cell p = q − o sees q at offset +o; cells of one offset are distinct (no add.at)
            self.sums[flat - off_flat[k]] += sign * self._packed[k]
            if band_flat.size:
                kept = band_z - self.offsets[k, 2] <= self.z_cap
                self.sums[band_flat[kept] - off_flat[k]] += sign * self._packed[k]

    def read(self, idx: np.ndarray) -> np.ndarray:
        """(5, N) int64 sums at voxels `idx` (must lie inside the box)."""
        return unpack_fields(self.sums[self._flat(idx)])


def _diff(old: np.ndarray, new: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Keys in `new` but not `old`, and in `old` but not `new` (both sorted unique)."""
    return _missing_from(new, old), _missing_from(old, new)


def _missing_from(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Values of sorted `a` not in sorted `b` (searchsorted: np.setdiff1d is far slower)."""
    if not b.size:
        return a
    pos = np.minimum(np.searchsorted(b, a), b.size - 1)
    return a[b[pos] != a]


class IncrementalFrontiers:
    """Alg. 1 on P* kept up to date between plans; `update` returns the same `PointFrontiers`
    as `lattice_frontiers` restricted to voxels whose centre is at most `z_max_m` high."""

    def __init__(self, voxel_m: float, radius_m: float, delta_d: float, delta_v_m2: float,
                 z_max_m: float = np.inf) -> None:
        self.voxel_m = voxel_m
        self.delta_d = delta_d
        self.delta_v_m2 = delta_v_m2
        self.z_max_m = z_max_m
        # cells above the highest voxel centre read are never needed: one lattice z past
        # z_max / voxel (≥ that centre's z: its float test is _low_enough's)
        z_cap = int(np.floor(z_max_m / voxel_m)) + 1 if np.isfinite(z_max_m) else None
        self.stats = LatticeStats(radius_m / voxel_m, z_cap)
        self.full_count = len(self.stats.offsets)
        self.full_var_m2 = full_ball_variance(self.stats.offsets) * voxel_m**2
        self.keys = np.zeros(0, np.int64)

    def update(self, keys: np.ndarray, added: np.ndarray | None = None,
               removed: np.ndarray | None = None) -> PointFrontiers:
        """Bring the sums to the sorted unique packed `keys`; `added` and `removed`
        (optional) = the keys new and gone since the previous call (saves the set
        difference; `removed` None: none)."""
        if added is None:
            added, removed = _diff(self.keys, keys)
        elif removed is None:
            removed = np.zeros(0, np.int64)
        self.stats.apply(unpack(removed), -1)
        self.stats.apply(unpack(added), +1)
        self.keys = keys
        idx = unpack(keys[self._low_enough(z_of(keys))])  # filtered first: unpack costs
        if idx.shape[0] >= COMPILED_FROM:
            return self._points_compiled(idx)
        if idx.shape[0] == 0:
            return self._points(idx, np.zeros((5, 0), np.int64))
        return self._points(idx, self.stats.read(idx))

    def _low_enough(self, z_idx: np.ndarray) -> np.ndarray:
        """(N,) whether each voxel's centre is at most z_max_m high: evaluated once per z
        level present (a few dozen), the same float expression as per voxel."""
        if z_idx.size == 0:
            return np.zeros(0, bool)
        z0 = int(z_idx.min())
        levels = np.arange(z0, int(z_idx.max()) + 1)
        return ((levels + 0.5) * self.voxel_m <= self.z_max_m)[z_idx - z0]

    def _points_compiled(self, idx: np.ndarray) -> PointFrontiers:
        """`_points` of the sums at `idx` in one compiled pass, bit for bit."""
        from services.edge_server.compiled_stats import voxel_stats  # numba: large maps only

        rho, var_m2, unexplored, weak = voxel_stats(
            self.stats.sums, self.stats._flat(idx), self.voxel_m, self.delta_d, self.delta_v_m2)
        return PointFrontiers(
            indices=idx, points_world=(idx + 0.5) * self.voxel_m, rho=rho, var_m2=var_m2,
            unexplored=unexplored, weak=weak, full_count=self.full_count,
            full_var_m2=self.full_var_m2)

    def _points(self, idx: np.ndarray, sums: np.ndarray) -> PointFrontiers:
        rho = sums[0]  # ≥ 1: a voxel counts itself
        mean = sums[1:4] / rho  # the kernel's exact float steps: same masks at δ_v ties
        var_vox = sums[4] / rho - (mean**2).sum(axis=0)
        var_m2 = np.maximum(var_vox, 0.0) * self.voxel_m**2
        return PointFrontiers(
            indices=idx, points_world=(idx + 0.5) * self.voxel_m, rho=rho, var_m2=var_m2,
            unexplored=rho < self.delta_d, weak=var_m2 > self.delta_v_m2,
            full_count=self.full_count, full_var_m2=self.full_var_m2)
