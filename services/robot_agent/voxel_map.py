"""small_gicp's Gaussian voxel map with its LRU sweeps held back until they can remove a voxel.

small_gicp sweeps the map every `clear_cycle` inserts: it scans every voxel for ones not seen
within `horizon` inserts and then rebuilds the whole hash table, whatever it found. A voxel can
only be that old once the insert counter has passed the horizon, so sweeps before then change
nothing, yet with the agent's horizon (100 000 frames: no voxel is ever dropped in a mission)
they were about 80 % of an insert's cost and grew with the map (bench/bench_agent_replay.py).
Skipping exactly those sweeps leaves the map, and every registration against it, unchanged.
"""

from __future__ import annotations

import numpy as np
import small_gicp


class LazyLruVoxelMap(small_gicp.GaussianVoxelMap):
    """A `GaussianVoxelMap` whose LRU sweeps start only once the horizon can have passed."""

    def __init__(self, voxel_m: float, horizon: int, clear_cycle: int = 10) -> None:
        super().__init__(voxel_m)
        self.horizon = int(horizon)
        self.clear_cycle = int(clear_cycle)
        self.n_inserts = 0
        self.set_lru(self.horizon, self.clear_cycle)

    def insert(self, points: small_gicp.PointCloud, T: np.ndarray) -> None:  # noqa: N803
        # small_gicp increments its counter, then sweeps when it is a multiple of the cycle and
        # removes voxels last seen more than `horizon` inserts before it
        counter = self.n_inserts + 1
        cycle = self.clear_cycle if counter > self.horizon else counter + 1  # never divides
        self.set_lru(self.horizon, cycle)
        super().insert(points, T)
        self.n_inserts = counter
