"""The DRF's DBSCAN gives Open3D's labels exactly (the mission outputs depend on them)."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from services.common.dbscan import dbscan_labels


def _open3d_labels(points: np.ndarray, eps_m: float, min_points: int) -> np.ndarray:
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    return np.asarray(cloud.cluster_dbscan(eps_m, min_points, False))


@pytest.mark.parametrize("seed", range(8))
def test_labels_equal_open3d_on_random_clouds(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(25):
        n = int(rng.integers(1, 300))
        points = rng.uniform(0.0, rng.uniform(0.2, 2.0), (n, 3))
        blob = rng.normal(0.0, 0.05, (int(rng.integers(0, 60)), 3)) + 1.0
        points = np.concatenate([points, blob])
        eps, min_points = float(rng.uniform(0.03, 0.2)), int(rng.integers(1, 8))
        np.testing.assert_array_equal(dbscan_labels(points, eps, min_points),
                                      _open3d_labels(points, eps, min_points))


def test_a_border_point_between_two_clusters_joins_the_first_grown() -> None:
    # two rows of 4 points, 0.19 m apart; the middle point reaches one point of each (< 0.1 m)
    # and has too few neighbours to be core itself
    left = np.array([[x, 0.0, 0.0] for x in (0.0, 0.01, 0.02, 0.03)])
    right = left + [0.22, 0.0, 0.0]
    middle = np.array([[0.125, 0.0, 0.0]])
    points = np.concatenate([right, middle, left])  # the right blob holds the lowest index
    labels = dbscan_labels(points, 0.1, 4)
    assert labels[:4].tolist() == [0] * 4 and labels[5:].tolist() == [1] * 4
    assert labels[4] == 0
    np.testing.assert_array_equal(labels, _open3d_labels(points, 0.1, 4))


def test_empty_and_all_noise() -> None:
    assert dbscan_labels(np.zeros((0, 3)), 0.1, 3).shape == (0,)
    far = np.array([[0.0, 0, 0], [5.0, 0, 0], [10.0, 0, 0]])
    assert dbscan_labels(far, 0.1, 2).tolist() == [-1, -1, -1]


@pytest.mark.parametrize("seed", range(4))
def test_lowest_connected_matches_scipy_components(seed: int) -> None:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from services.common.dbscan import lowest_connected

    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 400))
    edges = rng.integers(0, n, (int(rng.integers(0, 2 * n)), 2))
    chain = np.stack([np.arange(n - 1, 0, -1), np.arange(n - 2, -1, -1)], 1)[: n // 3]
    edges = np.concatenate([edges, chain])  # a long path numbered backwards
    root = lowest_connected(n, edges)
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    lowest = {c: int(np.flatnonzero(comp == c).min()) for c in np.unique(comp)}
    assert root.tolist() == [lowest[c] for c in comp]
