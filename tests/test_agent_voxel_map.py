"""The registration map with held-back LRU sweeps behaves as small_gicp's own."""

from __future__ import annotations

import numpy as np
import small_gicp

from services.robot_agent.voxel_map import LazyLruVoxelMap


def _frames(n: int) -> list[small_gicp.PointCloud]:
    """Clouds that walk along x, so old voxels stop being seen."""
    rng = np.random.default_rng(4)
    out = []
    for k in range(n):
        pts = rng.uniform([0.3 * k, -1.0, 0.1], [0.3 * k + 1.0, 1.0, 1.0], (600, 3))
        out.append(small_gicp.preprocess_points(pts, 0.08, num_neighbors=10, num_threads=1)[0])
    return out


def _plain(voxel_m: float, horizon: int) -> small_gicp.GaussianVoxelMap:
    vm = small_gicp.GaussianVoxelMap(voxel_m)
    vm.set_lru(horizon, 10)
    return vm


def test_same_voxels_dropped_as_small_gicps_lru() -> None:
    frames = _frames(45)
    lazy, plain = LazyLruVoxelMap(0.1, horizon=12), _plain(0.1, 12)
    sizes = []
    for cloud in frames:
        lazy.insert(cloud, np.eye(4))
        plain.insert(cloud, np.eye(4))
        sizes.append((lazy.size(), plain.size()))
    assert all(a == b for a, b in sizes)
    assert sizes[-1][0] < max(s for s, _ in sizes)  # the sweeps did drop voxels


def test_same_registration_before_the_horizon() -> None:
    frames = _frames(25)
    lazy, plain = LazyLruVoxelMap(0.05, horizon=100_000), _plain(0.05, 100_000)
    for cloud in frames[:-1]:
        lazy.insert(cloud, np.eye(4))
        plain.insert(cloud, np.eye(4))
    guess = np.eye(4)
    guess[:3, 3] = (0.03, -0.02, 0.0)
    a = small_gicp.align(lazy, frames[-1], guess, max_correspondence_distance=0.3, num_threads=1)
    b = small_gicp.align(plain, frames[-1], guess, max_correspondence_distance=0.3,
                         num_threads=1)
    assert lazy.size() == plain.size()
    assert np.array_equal(a.T_target_source, b.T_target_source)
    assert a.num_inliers == b.num_inliers
