"""DBSCAN with Open3D's labels, on scipy: the DRF's clustering without importing Open3D.

Importing open3d costs each agent process about 0.9 s of CPU (it loads its plotly and dash
viewers with it), more than all the clustering of a mission. This gives the labels
`open3d.geometry.PointCloud.cluster_dbscan` gives:

- a point is core when it has at least `min_points` points within `eps_m` (itself included);
- clusters are the connected components of core points (core neighbours within `eps_m`),
  numbered in the order of their lowest point index (Open3D grows one cluster at a time,
  seeded by the lowest unlabelled core point);
- a border point (not core, a core point within `eps_m`) takes the lowest-numbered cluster among
  its core neighbours (the first one grown reaches it first); every other point is noise, -1.

Open3D's radius search keeps distances < eps and scipy's ≤ eps: they differ only for points
exactly eps apart, which real-valued depth points are not.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree


def dbscan_labels(points: np.ndarray, eps_m: float, min_points: int) -> np.ndarray:
    """(N,) int64 cluster labels of (N, 3) points, -1 for noise (Open3D's numbering)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = points.shape[0]
    labels = np.full(n, -1, dtype=np.int64)
    if n == 0:
        return labels
    pairs = cKDTree(points).query_pairs(eps_m, output_type="ndarray")
    core = np.bincount(pairs.ravel(), minlength=n) + 1 >= min_points
    core_idx = np.flatnonzero(core)
    if core_idx.size == 0:
        return labels
    both = core[pairs[:, 0]] & core[pairs[:, 1]]
    edges = pairs[both]
    graph = coo_matrix((np.ones(len(edges), np.int8), (edges[:, 0], edges[:, 1])), shape=(n, n))
    n_comp, comp = connected_components(graph, directed=False)
    first_core = np.full(n_comp, n, dtype=np.int64)
    np.minimum.at(first_core, comp[core_idx], core_idx)
    used = np.flatnonzero(first_core < n)  # components holding a core point
    rank = np.full(n_comp, -1, dtype=np.int64)
    rank[used[np.argsort(first_core[used])]] = np.arange(used.size)
    labels[core_idx] = rank[comp[core_idx]]
    _label_borders(labels, core, pairs)
    return labels


def _label_borders(labels: np.ndarray, core: np.ndarray, pairs: np.ndarray) -> None:
    """Border points take the lowest label among their core neighbours (in place)."""
    a, b = pairs[:, 0], pairs[:, 1]
    core_a, core_b = core[a], core[b]
    border = np.concatenate([b[core_a & ~core_b], a[core_b & ~core_a]])
    via = np.concatenate([a[core_a & ~core_b], b[core_b & ~core_a]])
    if border.size == 0:
        return
    best = np.full(labels.shape, np.iinfo(np.int64).max, dtype=np.int64)
    np.minimum.at(best, border, labels[via])
    hit = best < np.iinfo(np.int64).max
    labels[hit] = best[hit]
