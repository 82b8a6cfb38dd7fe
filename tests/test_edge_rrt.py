"""RRT frontier detection (rrt.py): the tree kept between plans reaches far frontiers."""

from __future__ import annotations

import numpy as np

from services.common.grid import GridSpec
from services.edge_server.rrt import kept_points, rrt_frontier_mask


def _corridor() -> tuple[np.ndarray, np.ndarray]:
    """A 3-cell-wide corridor 150 cells long, known and free but for its far end."""
    traversable = np.zeros((20, 160), bool)
    traversable[8:11, 2:150] = True
    known = np.ones_like(traversable)
    known[8:11, 150:] = False
    return traversable, known


def test_a_kept_tree_reaches_the_frontier_a_fresh_one_misses() -> None:
    traversable, known = _corridor()
    start = [(9, 5)]
    fresh_found = kept_found = False
    tree = None
    for plan in range(40):
        fresh, _ = rrt_frontier_mask(traversable, known, start, 60, 5.0,
                                     np.random.default_rng([1, plan]))
        fresh_found |= bool(fresh.any())
        kept, tree = rrt_frontier_mask(traversable, known, start, 60, 5.0,
                                       np.random.default_rng([1, plan]), tree)
        kept_found |= bool(kept.any())
    assert kept_found and not fresh_found
    assert np.all(traversable[tuple(np.round(tree).astype(int).T)])  # nodes on free cells only
    r, c = np.argwhere(kept)[0]
    assert c >= 150 and 8 <= r <= 10


def test_tree_nodes_now_blocked_are_dropped() -> None:
    traversable, known = _corridor()
    _, tree = rrt_frontier_mask(traversable, known, [(9, 5)], 200, 5.0,
                                np.random.default_rng(0))
    assert len(tree) > 0
    traversable[:, :60] = False  # a door closed on the first stretch
    _, tree2 = rrt_frontier_mask(traversable, known, [(9, 100)], 0, 5.0,
                                 np.random.default_rng(0), tree)
    assert np.all(np.round(tree2[:, 1]) >= 60)


def test_rrt_frontier_points_stay_until_their_cell_is_known() -> None:
    spec = GridSpec(-1.0, -2.0, 0.1, 40, 40)  # x from -1, y from -2
    points_yx = np.array([[0.05, 0.05], [1.05, 1.05], [50.0, 50.0]])  # last: off grid
    known = np.zeros(spec.shape, bool)
    kept = kept_points(points_yx, known, spec)
    assert kept.sum() == 2 and kept[20, 10] and kept[30, 20]
    known[20, 10] = True  # (y, x) = (0.05, 0.05) seen since
    assert kept_points(points_yx, known, spec).sum() == 1
