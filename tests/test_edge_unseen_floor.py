"""Unseen floor patches: free grid cells whose floor no camera returned become F_u regions."""

from __future__ import annotations

import numpy as np

from services.common.grid import GridSpec
from services.common.voxels import pack, unpack, xy_of, z_of
from services.edge_server.config import EdgeConfig
from services.edge_server.planner import EdgePlanner
from services.edge_server.unseen_floor import (
    FULL_ENTROPY,
    floor_seen_cells,
    unseen_floor_mask,
    unseen_floor_regions,
)
from tests.test_edge_map import make_submap, voxel_centres
from tests.test_edge_planning import pose

V = 0.05
SPEC = GridSpec(origin_x=0.0, origin_y=0.0, resolution_m=V, height=80, width=80)


def floor_keys(cols: range, rows: range, k: int = 0) -> np.ndarray:
    return pack(np.array([[i, j, k] for i in cols for j in rows], np.int64))


def test_key_columns_without_unpacking() -> None:
    ijk = np.random.default_rng(0).integers(-2**20, 2**20, (500, 3))
    keys = pack(ijk)
    i, j = xy_of(keys)
    assert (np.stack([i, j, z_of(keys)], 1) == unpack(keys)).all() and (i == ijk[:, 0]).all()


def test_only_low_voxels_count_as_floor_returns() -> None:
    keys = np.concatenate([floor_keys(range(0, 5), range(0, 5)),  # centres at 0.025 m
                           floor_keys(range(10, 15), range(0, 5), k=6)])  # 0.325 m: a table
    seen = floor_seen_cells(keys, V, 0.1, SPEC)
    assert seen[:5, :5].all() and seen.sum() == 25


def test_an_unseen_half_room_is_one_region_with_its_goal_inside() -> None:
    free = np.ones(SPEC.shape, bool)
    keys = floor_keys(range(0, 40), range(0, 80))  # x < 2 m returned, x ≥ 2 m never
    config = EdgeConfig(planner="space", floor_unseen_min_m2=1.0)
    fs = unseen_floor_regions(keys, V, free, free, SPEC, config)
    assert len(fs) == 1
    # 2 m × 4 m less the seen radius (0.1 m) at x = 2 m and the erosion (0.1 m) at every edge
    assert fs.sizes[0] == (40 - 2 - 2 - 2) * (80 - 2 - 2)
    assert fs.goal_xy[0, 0] > 2.1 and fs.centroid_z[0] == 0 and not fs.weak[0]
    assert fs.gain[0] == FULL_ENTROPY
    # the same patch under the minimum area is no region
    small = config.model_copy(update={"floor_unseen_min_m2": 7.0})
    assert len(unseen_floor_regions(keys, V, free, free, SPEC, small)) == 0


def test_slivers_along_walls_and_cells_near_returns_are_not_patches() -> None:
    free = np.ones(SPEC.shape, bool)
    seen = np.ones(SPEC.shape, bool)
    seen[:, 40:43] = False  # a strip of 15 cm without returns (a depth edge's dropouts)
    seen[10, 10] = False  # one missing cell inside returned floor
    config = EdgeConfig(floor_seen_radius_m=0.0, floor_unseen_erode_m=0.1)
    assert not unseen_floor_mask(free, seen, SPEC, config).any()
    wide = seen.copy()
    wide[:, 40:50] = False  # half a metre wide: kept, less 0.1 m on each side
    mask = unseen_floor_mask(free, wide, SPEC, config)
    assert mask[2:-2, 42:48].all() and mask.sum() == 6 * 76
    # occupied or unknown cells are never unseen floor
    assert not unseen_floor_mask(np.zeros(SPEC.shape, bool), wide, SPEC, config).any()


def corridor_with_floor(config: EdgeConfig) -> EdgePlanner:
    """A 4 m × 1 m free strip whose floor was returned for x < 1.5 m only (its rim unknown)."""
    planner = EdgePlanner(config, tick_s=0.1)
    cols, rows = np.meshgrid(np.arange(0, 80), np.arange(20, 40))
    free = np.stack([cols.ravel(), rows.ravel()], axis=1)
    floor = voxel_centres([[i, j, 0] for i in range(0, 30) for j in range(20, 40)])
    planner.on_submap(make_submap(0, 0, 0, 1, np.eye(4), floor, free))
    planner.on_pose(pose(0, 0.5, 1.5))
    return planner


def far_floor(planner: EdgePlanner) -> list[int]:
    out = planner.plan(10)
    return [f.size for f in out.frontiers.frontiers if f.centroid[0] > 2.0 and f.centroid[2] == 0]


def test_space_offers_unseen_floor_always_or_only_in_the_endgame() -> None:
    base = dict(planner="space", space_grid_fallback=False, floor_unseen_min_m2=0.5)
    assert far_floor(corridor_with_floor(EdgeConfig(**base, floor_unseen_when="always"))) \
        == [(80 - 30 - 2 - 2 - 2) * (20 - 2 - 2)]  # seen radius, erosion at both ends
    off = dict(base, floor_unseen_min_m2=0.0, floor_unseen_when="always")
    assert far_floor(corridor_with_floor(EdgeConfig(**off))) == []
    # the returned floor's rim is an F_u region of its own: the endgame waits for it ...
    assert far_floor(corridor_with_floor(EdgeConfig(**base, complete_unexplored_fraction=0.0))) \
        == []
    # ... unless it is down to the tail's fraction of the map
    assert len(far_floor(corridor_with_floor(EdgeConfig(**base,
                                                        complete_unexplored_fraction=0.9)))) == 1


def test_a_sparse_scatter_of_far_returns_leaves_the_floor_unseen() -> None:
    free = np.ones(SPEC.shape, bool)
    rng = np.random.default_rng(3)
    seen = np.zeros(SPEC.shape, bool)
    seen[:, :40] = True  # x < 2 m returned from close by
    seen[:, 40:] = rng.random((80, 40)) < 0.01  # beyond: a grazing return here and there
    config = EdgeConfig(floor_unseen_min_m2=1.0)
    mask = unseen_floor_mask(free, seen, SPEC, config)
    assert not mask[:, :38].any() and mask[10:-10, 50:-10].mean() > 0.8
    # judged by the nearest return alone, the scatter breaks the patch up
    nearest = config.model_copy(update={"floor_seen_window_m": 0.0})
    assert unseen_floor_mask(free, seen, SPEC, nearest)[10:-10, 50:-10].mean() < 0.5


def room_with_a_hole(config: EdgeConfig) -> EdgePlanner:
    """A 4 m × 3 m room, its floor returned everywhere but in a 1 m² hole the grid never
    saw (unknown: no rays crossed it), walls all round."""
    planner = EdgePlanner(config, tick_s=0.1)
    cells = [(i, j) for i in range(80) for j in range(60)
             if not (50 <= i < 70 and 20 <= j < 40)]
    wall = [(i, j) for i in range(-1, 81) for j in (-1, 60)] + \
           [(i, j) for i in (-1, 80) for j in range(60)]
    points = voxel_centres([[i, j, 0] for i, j in cells]
                           + [[i, j, k] for i, j in wall for k in range(1, 8)])
    planner.on_submap(make_submap(0, 0, 0, 1, np.eye(4), points, np.array(cells)))
    planner.on_pose(pose(0, 0.5, 1.5))
    return planner


def full_entropy_regions(planner: EdgePlanner) -> list[int]:
    return [f.size for f in planner.plan(10).frontiers.frontiers if f.gain == FULL_ENTROPY]


def test_the_endgame_offers_the_grids_long_frontiers_too() -> None:
    base = dict(planner="space", space_grid_fallback=False, complete_unexplored_fraction=0.9)
    sizes = full_entropy_regions(room_with_a_hole(EdgeConfig(**base)))
    assert len(sizes) == 1 and 60 <= sizes[0] <= 84  # the hole's rim, 4 m
    off = EdgeConfig(**base, floor_endgame_grid_frontiers=False)
    assert full_entropy_regions(room_with_a_hole(off)) == []
    # outside the endgame (the tail still large) they wait
    early = EdgeConfig(**dict(base, complete_unexplored_fraction=0.0))
    assert full_entropy_regions(room_with_a_hole(early)) == []
