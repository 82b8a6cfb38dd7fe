"""Grid path planning: obstacle inflation, 8-connected A* and Dijkstra distance fields.

Moves are 8-connected; a diagonal costs √2 cells. A diagonal move may not cut the corner of a
blocked cell (both side neighbours must be traversable), so paths stay executable.
"""

from __future__ import annotations

import heapq
import logging
import math
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

log = logging.getLogger(__name__)
SQRT2 = math.sqrt(2.0)
_MOVES = [(-1, 0, 1.0), (1, 0, 1.0), (0, -1, 1.0), (0, 1, 1.0),
          (-1, -1, SQRT2), (-1, 1, SQRT2), (1, -1, SQRT2), (1, 1, SQRT2)]


def disk(radius_cells: int) -> np.ndarray:
    """Boolean disk structuring element of the given radius in cells."""
    r = int(radius_cells)
    yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
    return xx * xx + yy * yy <= r * r


def inflate(occupied: np.ndarray, radius_cells: int) -> np.ndarray:
    """Occupied cells grown by a disk of `radius_cells` (the robot's radius): the same cells
    as `ndimage.binary_dilation(occupied, disk(r))` (`dilate_disk` with r²)."""
    return dilate_disk(occupied, int(radius_cells) ** 2)


def dilate_disk(mask: np.ndarray, r2: int) -> np.ndarray:
    """`mask` grown by the disk of the cell offsets (dy, dx) with dy² + dx² ≤ `r2`, built row
    by row of the disk. Each of its rows is a run of half-width ⌊√(r2 − dy²)⌋, so the
    dilation is one running maximum along the rows per half-width, shifted by dy and OR-ed
    (a few passes over the grid instead of one per disk cell)."""
    mask = np.asarray(mask, dtype=bool)
    r2 = int(r2)
    if r2 <= 0 or not mask.any():
        return mask.copy()
    r = math.isqrt(r2)
    H = mask.shape[0]
    runs: dict[int, np.ndarray] = {}
    out = np.zeros_like(mask)
    for dy in range(-r, r + 1):
        w = math.isqrt(r2 - dy * dy)
        if w not in runs:
            runs[w] = ndimage.maximum_filter1d(mask.view(np.uint8), 2 * w + 1, axis=1,
                                               mode="constant", cval=0).view(bool)
        if abs(dy) < H:  # the disk is symmetric: out[y] |= run[y + dy]
            src, dst = slice(max(dy, 0), H + min(dy, 0)), slice(max(-dy, 0), H - max(dy, 0))
            out[dst] |= runs[w][src]
    return out


def _graph(traversable: np.ndarray) -> csr_matrix:
    """The allowed moves between traversable cells as a CSR matrix over flat cell indices,
    built row by row directly (each cell's moves in `_MOVES` order): no COO-to-CSR sort, which
    cost 0.5 s of a 0.6 s build on the warehouse's 600k-cell grid (bench/bench_planning.py).
    Dijkstra's distances do not depend on the order of a row's edges."""
    H, W = traversable.shape
    padded = np.pad(traversable, 1)

    def shifted(dr: int, dc: int) -> np.ndarray:
        return padded[1 + dr : 1 + dr + H, 1 + dc : 1 + dc + W]

    moves = []
    for dr, dc, _ in _MOVES:
        ok = traversable & shifted(dr, dc)
        if dr and dc:  # no corner cutting
            ok &= shifted(dr, 0) & shifted(0, dc)
        moves.append(ok)
    ok = np.stack(moves, axis=-1).reshape(H * W, len(_MOVES))
    step = np.array([dr * W + dc for dr, dc, _ in _MOVES])
    targets = (np.arange(H * W)[:, None] + step[None, :])[ok]
    costs = np.broadcast_to(np.array([c for _, _, c in _MOVES]), ok.shape)[ok]
    indptr = np.zeros(H * W + 1, np.int64)
    np.cumsum(ok.sum(axis=1), out=indptr[1:])
    return csr_matrix((costs, targets, indptr), shape=(H * W, H * W))


# cells × starts from which the compiled search pays for numba's import and cache load (0.5-0.7
# CPU-s, once per process): the warehouse's windows (200k cells, 9 starts a call), not the
# rooms' (a house window is 50-100k cells with 3-6 starts, a few ms a start with scipy)
COMPILED_MIN_WORK = 1_000_000
# The edge's goal assignment needs several robots' fields at once, after the merger's worker
# is done and while the lockstep clock waits for the plan: the second core is idle then.
FIELD_THREADS = 2


def distance_fields(traversable: np.ndarray, starts_rc: list[tuple[int, int]]) -> np.ndarray:
    """(K, H, W) path lengths in cells from each start; inf where unreachable.

    Large searches run compiled (`compiled_distance_fields`, about 3× faster on the
    warehouse's grids: bench/bench_distance_fields.py), small ones on scipy's Dijkstra
    (`scipy_distance_fields`); the two agree to the last bit."""
    traversable = np.asarray(traversable, dtype=bool)
    if traversable.size * len(starts_rc) >= COMPILED_MIN_WORK:
        return compiled_distance_fields(traversable, starts_rc)
    return scipy_distance_fields(traversable, starts_rc)


def compiled_distance_fields(traversable: np.ndarray, starts_rc: list[tuple[int, int]],
                             threads: int = FIELD_THREADS) -> np.ndarray:
    """`distance_fields` by a compiled bucket-queue Dijkstra (`grid_search`), the starts
    shared among up to `threads` threads (the search releases the GIL; each field is its
    own, so the result does not depend on the threads)."""
    from services.common.grid_search import field_into  # numba: only where fields are large

    traversable = np.asarray(traversable, dtype=bool)
    H, W = traversable.shape
    out = np.full((len(starts_rc), H, W), np.inf)
    free = np.pad(traversable, 1).reshape(-1)  # a blocked border: no bounds checks
    valid = [k for k, (r, c) in enumerate(starts_rc)
             if 0 <= r < H and 0 <= c < W and traversable[r, c]]

    def fill(k: int) -> None:
        r, c = starts_rc[k]
        dist = np.full((H + 2) * (W + 2), np.inf)
        field_into(free, W + 2, (int(r) + 1) * (W + 2) + int(c) + 1, dist)
        out[k] = dist.reshape(H + 2, W + 2)[1:-1, 1:-1]

    if threads > 1 and len(valid) > 1:
        with ThreadPoolExecutor(min(threads, len(valid))) as pool:
            list(pool.map(fill, valid))
    else:
        for k in valid:
            fill(k)
    return out


def scipy_distance_fields(traversable: np.ndarray, starts_rc: list[tuple[int, int]],
                          ) -> np.ndarray:
    """`distance_fields` by scipy's Dijkstra on the move graph (`_graph`; building it
    costs more than the searches, so it is built once for all starts)."""
    traversable = np.asarray(traversable, dtype=bool)
    H, W = traversable.shape
    out = np.full((len(starts_rc), H, W), np.inf)
    valid = [
        k for k, (r, c) in enumerate(starts_rc) if 0 <= r < H and 0 <= c < W and traversable[r, c]
    ]
    if not valid:
        return out
    graph = _graph(traversable)
    indices = [starts_rc[k][0] * W + starts_rc[k][1] for k in valid]
    out[valid] = dijkstra(graph, indices=indices).reshape(len(valid), H, W)
    return out


def reachable(traversable: np.ndarray, start_rc: tuple[int, int]) -> np.ndarray:
    """Cells reachable from `start_rc`. With no corner cutting, a diagonal step is allowed only
    when both side cells are free, so 8-connected reachability equals 4-connected labelling."""
    traversable = np.asarray(traversable, dtype=bool)
    r, c = start_rc
    H, W = traversable.shape
    if not (0 <= r < H and 0 <= c < W) or not traversable[r, c]:
        return np.zeros_like(traversable)
    labels, _ = ndimage.label(traversable)
    return labels == labels[r, c]


def distance_field(traversable: np.ndarray, start_rc: tuple[int, int]) -> np.ndarray:
    """Path length in cells from `start_rc` to every cell; inf where unreachable."""
    return distance_fields(traversable, [start_rc])[0]


# A* expansions past which a search is large (about 35 ms of Python; the warehouse's searches
# around its racks take tens of thousands): it is run compiled instead
# (`grid_search.astar_parents`, the same path, about 10× faster), and so is every later search
# of the process. The rooms' searches nearly all stay under it, so an agent there seldom
# imports numba (0.5-0.7 CPU-s per process, about its whole A* in a room mission).
ASTAR_PYTHON_BUDGET = 10_000
_astar_compiled = False


def astar(
    traversable: np.ndarray, start_rc: tuple[int, int], goal_rc: tuple[int, int]
) -> np.ndarray | None:
    """Shortest 8-connected path as (K, 2) int64 (row, col) including both ends, or None.

    Nodes are flat indices into the grid padded by one blocked cell, so a move needs no bounds
    check and reads one byte. A flat index orders like its (row, col), so heap ties break as
    they would on (row, col) tuples: the same path whatever the representation."""
    global _astar_compiled
    grid = np.asarray(traversable, dtype=bool)
    H, W = grid.shape
    start, goal = (int(start_rc[0]), int(start_rc[1])), (int(goal_rc[0]), int(goal_rc[1]))
    for r, c in (start, goal):
        if not (0 <= r < H and 0 <= c < W) or not grid[r, c]:
            return None
    wp = W + 2
    padded = np.pad(grid, 1)  # 1 = traversable, border 0
    src, dst = (start[0] + 1) * wp + start[1] + 1, (goal[0] + 1) * wp + goal[1] + 1
    parent = (None if _astar_compiled
              else _search(padded.tobytes(), wp, src, dst, ASTAR_PYTHON_BUDGET))
    if parent is _OVER_BUDGET:
        log.info("an A* search past %d expansions: compiled from now on", ASTAR_PYTHON_BUDGET)
        _astar_compiled = True
    if _astar_compiled:
        parent = _compiled_search(padded.reshape(-1), wp, src, dst)
    if parent is None:
        return None
    path = [dst]
    while parent[path[-1]] >= 0:
        path.append(int(parent[path[-1]]))
    rc = np.divmod(np.array(path[::-1], dtype=np.int64), wp)
    return np.stack(rc, axis=1) - 1


def _compiled_search(free: np.ndarray, wp: int, src: int, dst: int) -> np.ndarray | None:
    from services.common.grid_search import astar_parents  # numba: only for large searches

    parent = np.full(free.size, -1, np.int64)
    return parent if astar_parents(free, wp, src, dst, parent) else None


_OVER_BUDGET: list[int] = []  # `_search`'s answer past `ASTAR_PYTHON_BUDGET` expansions


def _search(free: bytes, wp: int, src: int, dst: int, budget: float = math.inf,
            ) -> list[int] | None:
    """A* over flat indices of the padded grid; each node's parent (-1: none), or None when
    unreachable, or `_OVER_BUDGET` past `budget` expansions. Costs, parents and the closed
    set are flat lists indexed by node: a search that floods the grid (a goal behind a wall)
    runs about a fifth faster than with dicts."""
    # per move: flat offset, cost, the two side cells a diagonal must not cut (0: none), and
    # its (row, col) change, so the heuristic needs no divmod per neighbour
    table = [(dr * wp + dc, step, dr * wp if dr and dc else 0, dc if dr and dc else 0, dr, dc)
             for dr, dc, step in _MOVES]
    gr, gc = divmod(dst, wp)
    diag = SQRT2 - 1.0  # octile distance to the goal: diag · min + max
    sr, sc = divmod(src, wp)
    a, b = abs(sr - gr), abs(sc - gc)
    n = len(free)
    g = [math.inf] * n
    g[src] = 0.0
    parent = [-1] * n
    closed = bytearray(n)
    heap = [(diag * min(a, b) + max(a, b), 0.0, src)]
    push, pop = heapq.heappush, heapq.heappop
    while heap:
        _, cost, node = pop(heap)
        if node == dst:
            return parent
        if closed[node]:
            continue
        closed[node] = 1
        budget -= 1
        if budget < 0:
            return _OVER_BUDGET
        r, c = divmod(node, wp)
        for off, step, side_r, side_c, dr, dc in table:
            nxt = node + off
            if not free[nxt] or (side_r and not (free[node + side_r] and free[node + side_c])):
                continue
            new = cost + step
            if new < g[nxt]:
                g[nxt] = new
                parent[nxt] = node
                a, b = abs(r + dr - gr), abs(c + dc - gc)
                push(heap, (new + (diag * min(a, b) + max(a, b)), new, nxt))
    return None


def path_length(path_rc: np.ndarray) -> float:
    """Length in cells of a (K, 2) cell path."""
    if len(path_rc) < 2:
        return 0.0
    steps = np.abs(np.diff(path_rc, axis=0))
    return float(np.sum(np.where(steps.sum(axis=1) == 2, SQRT2, 1.0)))


def nearest_traversable(traversable: np.ndarray, rc: tuple[int, int]) -> tuple[int, int] | None:
    """The traversable cell closest (Euclidean) to `rc`, or None if there is none."""
    grid = np.asarray(traversable, dtype=bool)
    cells = np.argwhere(grid)
    if cells.size == 0:
        return None
    d2 = ((cells - np.asarray(rc)) ** 2).sum(axis=1)
    r, c = cells[int(np.argmin(d2))]
    return int(r), int(c)
