"""A* (8-connected, √2 diagonals) against Dijkstra on random grids."""

from __future__ import annotations

import numpy as np

from services.common.planning import astar, distance_field, path_length


def test_astar_matches_dijkstra_on_random_grids() -> None:
    rng = np.random.default_rng(4)
    checked = 0
    for _ in range(30):
        trav = rng.random((30, 40)) > 0.3
        free = np.argwhere(trav)
        s, g = free[rng.integers(len(free))], free[rng.integers(len(free))]
        dist = distance_field(trav, (int(s[0]), int(s[1])))
        path = astar(trav, (int(s[0]), int(s[1])), (int(g[0]), int(g[1])))
        if not np.isfinite(dist[g[0], g[1]]):
            assert path is None
            continue
        assert path is not None and trav[path[:, 0], path[:, 1]].all()
        assert np.abs(np.diff(path, axis=0)).max() <= 1
        assert np.isclose(path_length(path), dist[g[0], g[1]])
        checked += 1
    assert checked >= 10
