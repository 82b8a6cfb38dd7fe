"""Shared grid geometry and planning: reachability, distance fields, A*, inflation."""

from __future__ import annotations

import numpy as np

from services.common.grid import GridSpec
from services.common.planning import (
    astar,
    distance_field,
    distance_fields,
    inflate,
    nearest_traversable,
    path_length,
    reachable,
)


def test_reachable_matches_dijkstra_on_random_grids() -> None:
    rng = np.random.default_rng(2)
    for _ in range(40):
        grid = rng.random((30, 40)) > 0.35
        grid[0, 0] = True
        assert np.array_equal(reachable(grid, (0, 0)), np.isfinite(distance_field(grid, (0, 0))))


def test_no_corner_cutting() -> None:
    grid = np.array([[1, 0], [0, 1]], dtype=bool)
    assert not reachable(grid, (0, 0))[1, 1]
    assert astar(grid, (0, 0), (1, 1)) is None


def test_distance_fields_share_one_graph() -> None:
    rng = np.random.default_rng(5)
    grid = rng.random((25, 25)) > 0.3
    starts = [tuple(map(int, rc)) for rc in np.argwhere(grid)[:3]] + [(-1, 4)]
    stack = distance_fields(grid, starts)
    for k, start in enumerate(starts[:3]):
        assert np.array_equal(stack[k], distance_field(grid, start))
        goal = tuple(map(int, np.argwhere(np.isfinite(stack[k]))[-1]))
        path = astar(grid, start, goal)
        assert path is not None and abs(path_length(path) - stack[k][goal]) < 1e-9
    assert np.isinf(stack[3]).all()


def test_inflate_and_nearest() -> None:
    occupied = np.zeros((11, 11), dtype=bool)
    occupied[5, 5] = True
    grown = inflate(occupied, 2)
    assert grown[5, 3] and grown[3, 5] and not grown[3, 3] and grown.sum() == 13
    r, c = nearest_traversable(~grown, (5, 5))
    assert (r - 5) ** 2 + (c - 5) ** 2 == 5  # just outside the radius-2 disk


def test_grid_spec_round_trip() -> None:
    spec = GridSpec.covering(np.array([-1.02, 2.0]), np.array([3.0, 4.51]), 0.05)
    xy = np.array([[-1.0, 2.01], [2.99, 4.5]])
    rc = spec.cell_of(xy)
    assert spec.contains(rc).all()
    assert np.allclose(spec.centre_of(rc), xy, atol=0.025 + 1e-9)
