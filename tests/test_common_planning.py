"""Shared grid geometry and planning: reachability, distance fields, A*, inflation."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from services.common import planning
from services.common.grid import GridSpec
from services.common.planning import (
    COMPILED_MIN_WORK,
    astar,
    compiled_distance_fields,
    dilate_disk,
    disk,
    distance_field,
    distance_fields,
    inflate,
    nearest_traversable,
    path_length,
    reachable,
    scipy_distance_fields,
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


def _reference_fields(grid: np.ndarray, starts: list[tuple[int, int]]) -> np.ndarray:
    """Dijkstra on a graph built edge by edge in COO form (how the planner built it before
    its direct CSR build), for the exact comparison below."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    H, W = grid.shape
    src, dst, cost = [], [], []
    for r, c in np.argwhere(grid):
        for dr, dc in [(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)]:
            rr, cc = r + dr, c + dc
            if not (0 <= rr < H and 0 <= cc < W and grid[rr, cc]):
                continue
            if dr and dc and not (grid[r + dr, c] and grid[r, c + dc]):
                continue
            src.append(r * W + c)
            dst.append(rr * W + cc)
            cost.append(np.sqrt(2.0) if dr and dc else 1.0)
    graph = coo_matrix((cost, (src, dst)), shape=(H * W, H * W)).tocsr()
    return dijkstra(graph, indices=[r * W + c for r, c in starts]).reshape(len(starts), H, W)


def test_distance_fields_equal_a_graph_built_edge_by_edge() -> None:
    rng = np.random.default_rng(11)
    for _ in range(25):
        H, W = (int(n) for n in rng.integers(1, 30, 2))
        grid = rng.random((H, W)) < rng.uniform(0.4, 0.95)
        cells = np.argwhere(grid)
        if len(cells) == 0:
            continue
        starts = [tuple(map(int, cells[i])) for i in rng.integers(0, len(cells), 3)]
        reference = _reference_fields(grid, starts)
        assert np.array_equal(distance_fields(grid, starts), reference)
        assert np.array_equal(compiled_distance_fields(grid, starts), reference)
        # one thread or several: each start's field is its own
        assert np.array_equal(compiled_distance_fields(grid, starts, threads=1), reference)
        with_outside = compiled_distance_fields(grid, [(-1, 0), *starts], threads=3)
        assert np.isinf(with_outside[0]).all() and np.array_equal(with_outside[1:], reference)


def test_distance_fields_equal_scipys_dijkstra_on_large_grids() -> None:
    """The compiled search (which large searches take) against scipy's on grids whose fronts
    outgrow its first buffers (an open 520 × 520 square) and on long corridors (hundreds of
    buckets), bit for bit."""
    rng = np.random.default_rng(5)
    open_square = np.ones((520, 520), bool)
    aisles = np.ones((600, 450), bool)
    for c in range(10, 440, 12):
        aisles[20:580, c : c + 5] = False
    aisles[rng.random(aisles.shape) < 0.03] = False
    for grid in (open_square, aisles):
        cells = np.argwhere(grid)
        starts = [tuple(map(int, cells[i])) for i in rng.integers(0, len(cells), 3)]
        starts.append((-1, 4))  # outside: all inf
        assert grid.size * len(starts) >= COMPILED_MIN_WORK  # the compiled search's size
        fields = distance_fields(grid, starts)
        assert np.array_equal(fields, scipy_distance_fields(grid, starts))
        assert np.isinf(fields[-1]).all() and np.isfinite(fields[0]).sum() > 0.9 * grid.sum()


def test_inflate_and_nearest() -> None:
    occupied = np.zeros((11, 11), dtype=bool)
    occupied[5, 5] = True
    grown = inflate(occupied, 2)
    assert grown[5, 3] and grown[3, 5] and not grown[3, 3] and grown.sum() == 13
    r, c = nearest_traversable(~grown, (5, 5))
    assert (r - 5) ** 2 + (c - 5) ** 2 == 5  # just outside the radius-2 disk


def test_inflate_equals_a_disk_dilation() -> None:
    """Row-run inflation marks the cells `binary_dilation` by the disk marks: random grids,
    radii 1-8, grids narrower than the disk, obstacles on the border."""
    rng = np.random.default_rng(6)
    for _ in range(200):
        shape = tuple(int(n) for n in rng.integers(1, 40, 2))
        occupied = rng.random(shape) < rng.choice([0.005, 0.05, 0.3])
        occupied[0, -1] = True
        r = int(rng.integers(1, 9))
        want = ndimage.binary_dilation(occupied, structure=disk(r))
        assert np.array_equal(inflate(occupied, r), want)


def test_dilate_disk_by_any_squared_radius_equals_a_dilation_by_those_offsets() -> None:
    """`dilate_disk(mask, r2)` marks what `binary_dilation` by the offsets with dy² + dx² ≤
    r2 marks, r2 not a square included (the edge's nearness to unknown cells)."""
    rng = np.random.default_rng(7)
    for _ in range(200):
        shape = tuple(int(n) for n in rng.integers(1, 40, 2))
        mask = rng.random(shape) < rng.choice([0.005, 0.05, 0.3])
        r2 = int(rng.integers(0, 70))
        r = int(np.sqrt(r2))
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
        want = ndimage.binary_dilation(mask, structure=yy * yy + xx * xx <= r2) if r2 else mask
        assert np.array_equal(dilate_disk(mask, r2), want)


def test_grid_spec_round_trip() -> None:
    spec = GridSpec.covering(np.array([-1.02, 2.0]), np.array([3.0, 4.51]), 0.05)
    xy = np.array([[-1.0, 2.01], [2.99, 4.5]])
    rc = spec.cell_of(xy)
    assert spec.contains(rc).all()
    assert np.allclose(spec.centre_of(rc), xy, atol=0.025 + 1e-9)


def _reference_astar(grid: np.ndarray, start: tuple[int, int], goal: tuple[int, int]):
    """Textbook A* on (row, col) tuples: the path the agent followed before flat indices."""
    import heapq
    import math

    H, W = grid.shape
    octile = lambda a: (math.sqrt(2.0) - 1.0) * min(abs(a[0] - goal[0]), abs(a[1] - goal[1])) \
        + max(abs(a[0] - goal[0]), abs(a[1] - goal[1]))  # noqa: E731
    moves = [(-1, 0, 1.0), (1, 0, 1.0), (0, -1, 1.0), (0, 1, 1.0), (-1, -1, math.sqrt(2.0)),
             (-1, 1, math.sqrt(2.0)), (1, -1, math.sqrt(2.0)), (1, 1, math.sqrt(2.0))]
    g, parent, heap, closed = {start: 0.0}, {}, [(octile(start), 0.0, start)], set()
    while heap:
        _, cost, node = heapq.heappop(heap)
        if node == goal:
            path = [goal]
            while path[-1] in parent:
                path.append(parent[path[-1]])
            return np.array(path[::-1])
        if node in closed:
            continue
        closed.add(node)
        for dr, dc, step in moves:
            nr, nc = node[0] + dr, node[1] + dc
            if not (0 <= nr < H and 0 <= nc < W) or not grid[nr, nc]:
                continue
            if dr and dc and not (grid[nr, node[1]] and grid[node[0], nc]):
                continue
            if cost + step < g.get((nr, nc), math.inf):
                g[(nr, nc)], parent[(nr, nc)] = cost + step, node
                heapq.heappush(heap, (cost + step + octile((nr, nc)), cost + step, (nr, nc)))
    return None


def test_astar_takes_the_same_path_as_textbook_astar() -> None:
    """Not just as short: equal-cost paths abound on a grid, and the one taken (ties broken
    by row, then column) decides where the robot drives, so a faster A* must keep it."""
    rng = np.random.default_rng(11)
    for _ in range(150):
        H, W = (int(v) for v in rng.integers(2, 60, 2))
        grid = rng.random((H, W)) > rng.uniform(0.05, 0.4)
        cells = np.argwhere(grid)
        if len(cells) == 0:
            continue
        a, b = (tuple(int(v) for v in cells[i]) for i in rng.integers(len(cells), size=2))
        ref, got = _reference_astar(grid, a, b), astar(grid, a, b)
        assert (ref is None) == (got is None)
        if ref is not None:
            assert np.array_equal(ref, got) and got.dtype == np.int64


def test_the_compiled_astar_takes_the_same_path(monkeypatch) -> None:
    """The compiled A* (large searches) against the textbook one on random grids, and against
    the Python one on large grids with long walls, where a search floods thousands of
    cells and the heap outgrows its first arrays: the same cells, in the same order."""
    monkeypatch.setattr(planning, "_astar_compiled", True)
    rng = np.random.default_rng(12)
    for _ in range(150):
        H, W = (int(v) for v in rng.integers(2, 60, 2))
        grid = rng.random((H, W)) > rng.uniform(0.05, 0.4)
        cells = np.argwhere(grid)
        if len(cells) == 0:
            continue
        a, b = (tuple(int(v) for v in cells[i]) for i in rng.integers(len(cells), size=2))
        ref, got = _reference_astar(grid, a, b), astar(grid, a, b)
        assert (ref is None) == (got is None)
        if ref is not None:
            assert np.array_equal(ref, got) and got.dtype == np.int64
    grid = rng.random((260, 300)) > 0.1
    for c in range(20, 280, 40):  # walls with a gap at alternate ends
        grid[(0 if c % 80 else 20) : (240 if c % 80 else 260), c : c + 3] = False
    cells = np.argwhere(grid)
    for _ in range(6):
        a, b = (tuple(int(v) for v in cells[i]) for i in rng.integers(len(cells), size=2))
        W = grid.shape[1] + 2
        src, dst = (a[0] + 1) * W + a[1] + 1, (b[0] + 1) * W + b[1] + 1
        python = planning._search(np.pad(grid, 1).tobytes(), W, src, dst)
        compiled = planning._compiled_search(np.pad(grid, 1).reshape(-1), W, src, dst)
        assert (python is None) == (compiled is None)
        if python is not None:
            assert np.array_equal(np.array(python), compiled)


def test_a_search_over_the_budget_goes_on_compiled(monkeypatch) -> None:
    """Past `ASTAR_PYTHON_BUDGET` expansions a search is run compiled, with the same path,
    and so is every later one."""
    monkeypatch.setattr(planning, "_astar_compiled", False)
    monkeypatch.setattr(planning, "ASTAR_PYTHON_BUDGET", 50)
    grid = np.ones((40, 40), bool)
    grid[5:40, 20] = False
    assert np.array_equal(astar(grid, (39, 0), (39, 39)),
                          _reference_astar(grid, (39, 0), (39, 39)))
    assert planning._astar_compiled
    assert np.array_equal(astar(grid, (0, 0), (1, 1)), _reference_astar(grid, (0, 0), (1, 1)))
