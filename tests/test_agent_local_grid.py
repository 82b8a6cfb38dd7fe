"""Local grid: free along rays, occupied at hits, edge grid merge."""

from __future__ import annotations

import numpy as np

from schemas.messages import OccupancyGrid
from services.robot_agent.local_grid import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    LocalGrid,
    floor_rays,
    ray_samples,
)


def test_ray_samples_stop_short_of_the_hit() -> None:
    s = ray_samples(np.zeros(2), np.array([[1.0, 0.0], [0.0, -0.5]]), 0.025, 0.05)
    assert s[:, 0].max() <= 0.95 + 1e-9 and s[:, 1].min() >= -0.45 - 1e-9
    assert np.all((s[:, 0] == 0) | (s[:, 1] == 0))


def test_free_along_rays_and_occupied_at_hits() -> None:
    grid = LocalGrid.centred(0.0, 0.0, 5.0, 0.05)
    # a wall at x = 2 seen by rays fanning out from the origin at obstacle height
    ys = np.linspace(-1.0, 1.0, 41)
    wall_base = np.stack([np.full_like(ys, 2.0), ys, np.full_like(ys, 0.3)], 1)
    free = floor_rays(wall_base, np.zeros(2), 0.05, 0.6, 0.05, 0.01)
    grid.update(free, wall_base[:, :2])
    cells = grid.cells()
    rc = grid.spec.cell_of(np.array([[1.0, 0.0], [2.01, 0.0], [3.0, 0.0], [1.5, 0.5]]))
    assert cells[rc[0, 0], rc[0, 1]] == FREE
    assert cells[rc[1, 0], rc[1, 1]] == OCCUPIED
    assert cells[rc[2, 0], rc[2, 1]] == UNKNOWN  # behind the wall
    assert cells[rc[3, 0], rc[3, 1]] == FREE


def test_hits_outweigh_rays_passing_over() -> None:
    grid = LocalGrid.centred(0.0, 0.0, 5.0, 0.05)
    box = np.array([[1.0, 0.0]])
    for _ in range(5):  # same frame: the box is hit and a ray to the floor behind passes over it
        grid.update(ray_samples(np.zeros(2), np.array([[2.0, 0.0]]), 0.025, 0.0), box)
    rc = grid.spec.cell_of(box)
    assert grid.cells()[rc[0, 0], rc[0, 1]] == OCCUPIED


def test_edge_grid_fills_unknown_but_own_view_wins() -> None:
    grid = LocalGrid.centred(0.0, 0.0, 2.0, 0.05)
    grid.update(np.array([[0.52, 0.52]]), np.empty((0, 2)))
    edge_cells = np.full((20, 20), OCCUPIED, np.int8)  # covers [0, 1) × [0, 1)
    grid.merge_edge(OccupancyGrid(tick=0, resolution_m=0.05, origin_x=0.0, origin_y=0.0,
                                  cells=edge_cells))
    cells = grid.cells()
    own = grid.spec.cell_of(np.array([[0.52, 0.52], [0.2, 0.2], [-0.5, -0.5]]))
    assert cells[own[0, 0], own[0, 1]] == FREE
    assert cells[own[1, 0], own[1, 1]] == OCCUPIED
    assert cells[own[2, 0], own[2, 1]] == UNKNOWN
    # a misaligned edge grid is resampled by cell centres
    grid.merge_edge(OccupancyGrid(tick=1, resolution_m=0.05, origin_x=0.01, origin_y=0.0,
                                  cells=edge_cells))
    assert grid.cells()[own[1, 0], own[1, 1]] == OCCUPIED


def test_known_box_covers_exactly_the_edge_grids_known_cells() -> None:
    """The planner's window comes from this box: it must grow to the edge grid's known cells
    (found in the pasted window only), not to the whole pasted grid."""
    grid = LocalGrid.centred(0.0, 0.0, 2.0, 0.1)
    cells = np.full((10, 12), -1, np.int8)
    cells[3, 4], cells[7, 9] = 0, 100
    grid.merge_edge(OccupancyGrid(tick=0, origin_x=-1.0, origin_y=-0.5, resolution_m=0.1,
                                  cells=cells))
    known = np.argwhere(grid.edge != -1)
    assert known.tolist() == [[18, 14], [22, 19]]
    assert (grid.row_lo, grid.row_hi, grid.col_lo, grid.col_hi) == (18, 22, 14, 19)


def test_grid_grows_to_cover_a_goal_beyond_it() -> None:
    """A goal past the grid made at spawn (a world larger than it) grows the grid in whole
    cells: every known cell keeps its world place and value, the known box moves with the
    origin, and the edge's cells beyond the old bounds come in at the next merge."""
    grid = LocalGrid.centred(0.0, 0.0, 2.0, 0.05)
    grid.update(np.array([[0.52, 0.52], [-1.0, 1.5]]), np.array([[1.2, -0.3]]))
    before = grid.cells().copy()
    probe = np.array([[0.52, 0.52], [-1.0, 1.5], [1.2, -0.3], [1.9, 1.9]])
    values = grid.values_at(grid.spec.cell_of(probe))
    box = grid.window(0)
    assert not grid.cover(np.array([[1.9, 1.9]]), 0.5)  # inside: nothing to do
    assert grid.cover(np.array([[6.0, -4.0]]), 1.0)
    spec = grid.spec
    assert spec.contains(spec.cell_of(np.array([[6.99, -5.0], [-2.0, 1.99]]))).all()
    assert np.isclose(spec.origin_x, -2.0) and np.isclose(spec.origin_y, -5.0)
    assert np.array_equal(grid.values_at(spec.cell_of(probe)), values)
    assert (grid.cells() != UNKNOWN).sum() == (before != UNKNOWN).sum()
    new_box = grid.window(0)
    shift = round(3.0 / 0.05)  # the origin moved 3 m down in y (rows), 0 in x (cols)
    assert (new_box[0].start, new_box[0].stop) == (box[0].start + shift, box[0].stop + shift)
    assert (new_box[1].start, new_box[1].stop) == (box[1].start, box[1].stop)
    edge_cells = np.full((20, 20), OCCUPIED, np.int8)  # [5, 6) × [-4, -3): beyond the old grid
    grid.merge_edge(OccupancyGrid(tick=0, resolution_m=0.05, origin_x=5.0, origin_y=-4.0,
                                  cells=edge_cells))
    assert grid.values_at(spec.cell_of(np.array([[5.5, -3.5]])))[0] == OCCUPIED
