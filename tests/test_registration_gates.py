"""Pairwise registration gates: the fit's residual, the planar condition, the shift, the
faces paired back to back."""

from __future__ import annotations

import numpy as np
import pytest

from services.common.geometry import T_from_xyyaw, invert
from services.common.registration import (
    RegistrationParams,
    flat_normals,
    opposed_fraction,
    overlapping_pairs,
    planar_condition,
    prepare,
    register,
    world_box,
    world_boxes,
)
from services.config import load_config
from services.edge_server.merger import MapMerger, merger_params
from tests.test_edge_merger import crop, scene


def _corridor() -> np.ndarray:
    """Two long parallel walls and a floor at 2 cm: nothing pins a slide along x."""
    s = 0.02
    x, z = np.arange(0, 8.0, s), np.arange(0, 1.5, s)
    walls = [np.stack(np.meshgrid(x, [y], z), -1).reshape(-1, 3) for y in (0.0, 2.0)]
    floor = np.stack(np.meshgrid(x, np.arange(0, 2.0, s), [0.0]), -1).reshape(-1, 3)
    return np.concatenate([*walls, floor])


def test_planar_condition_is_one_for_isotropic_and_large_for_one_weak_direction() -> None:
    assert abs(planar_condition(np.eye(6)) - 1.0) < 1e-9
    H = np.eye(6)
    H[3, 3] = 1e-4  # x barely constrained
    assert planar_condition(H) > 1e3
    H[3, 3] = 0.0
    assert planar_condition(H) == float("inf")


def test_a_corridor_registration_passes_until_the_condition_gate_is_set() -> None:
    world = _corridor()
    T_a, T_b = T_from_xyyaw(3.0, 1.0, 0.0), T_from_xyyaw(4.0, 1.0, 0.0)
    params = RegistrationParams(sigma_m=0.05)
    a, b = prepare(crop(world, T_a), params), prepare(crop(world, T_b), params)
    T_init = invert(T_a) @ T_from_xyyaw(4.05, 1.03, 0.0)
    assert register(a, b, T_init, params) is not None
    gated = RegistrationParams(sigma_m=0.05, max_planar_condition=20.0)
    assert register(a, b, T_init, gated) is None


def test_the_residual_gate_rejects_a_poor_fit_and_keeps_a_good_one() -> None:
    world = scene()
    T_a, T_b = T_from_xyyaw(2.5, 2.0, 0.1), T_from_xyyaw(3.2, 2.1, 0.3)
    params = RegistrationParams(sigma_m=0.05, max_mean_error=0.015)
    a = prepare(crop(world, T_a), params)
    T_init = invert(T_a) @ T_from_xyyaw(3.24, 2.07, 0.31)
    clean = prepare(crop(world, T_b), params)
    result = register(a, clean, T_init, params)
    assert result is not None
    truth = invert(T_a) @ T_b
    assert np.linalg.norm(result.T_target_source[:2, 3] - truth[:2, 3]) < 0.02
    # the same view with its surfaces blurred by 4 cm: it still converges, but apart
    rng = np.random.default_rng(3)
    points_b = crop(world, T_b)
    blurred = prepare(points_b + rng.normal(0.0, 0.04, points_b.shape), params)
    assert register(a, blurred, T_init, RegistrationParams(sigma_m=0.05)) is not None
    assert register(a, blurred, T_init, params) is None


def test_the_shift_gate_rejects_a_registration_that_moves_the_estimate_too_far() -> None:
    world = scene()
    T_a, T_b = T_from_xyyaw(2.5, 2.0, 0.1), T_from_xyyaw(3.2, 2.1, 0.3)
    params = RegistrationParams(sigma_m=0.05)
    a, b = prepare(crop(world, T_a), params), prepare(crop(world, T_b), params)
    T_init = invert(T_a) @ T_from_xyyaw(3.32, 2.1, 0.3)  # 12 cm off
    assert register(a, b, T_init, params) is not None
    assert register(a, b, T_init, RegistrationParams(sigma_m=0.05, max_shift_m=0.08)) is None


def test_the_edge_config_sets_the_merger_gates_and_zero_turns_them_off() -> None:
    default = merger_params(load_config(None, {}).edge)
    gates = default.registration
    assert (gates.max_mean_error, gates.max_planar_condition, gates.max_shift_m) == (
        0.015, 20.0, 0.25)
    assert (default.max_registrations, default.registrations_per_robot, default.precheck_m) == (
        2, 0.34, 0.25)
    off = merger_params(load_config(None, {"edge.merge_max_mean_error": "0",
                                           "edge.merge_max_condition": "0"}).edge).registration
    assert off.max_mean_error == float("inf") and off.max_planar_condition == float("inf")
    scaled = merger_params(load_config(None, {"edge.merge_registrations_per_robot": "0.5"}).edge)
    assert scaled.registrations_per_robot == 0.5
    team = MapMerger(0.05, default)  # the pairs' rule: rooms keep 2, the warehouse gets 24
    assert [team.registration_budget(n) for n in (3, 6, 12, 24)] == [2, 2, 6, 24]


def _brute_pairs(boxes: np.ndarray, min_volume: float) -> list[tuple[int, int, float]]:
    side = (np.minimum(boxes[:, None, 1], boxes[None, :, 1])
            - np.maximum(boxes[:, None, 0], boxes[None, :, 0]))
    volume = np.prod(np.maximum(side, 0.0), axis=2)
    rows, cols = np.nonzero(np.triu(volume >= min_volume, 1))
    return sorted(zip(rows.tolist(), cols.tolist(), volume[rows, cols].tolist(), strict=True))


def test_the_sweep_finds_every_overlapping_pair_the_full_table_does() -> None:
    rng = np.random.default_rng(3)
    for n in (0, 1, 2, 40, 400):
        lo = rng.uniform(-15, 15, (n, 3)) * [1, 1, 0.1]  # flat like a floor's submaps
        boxes = np.stack([lo, lo + rng.uniform(0.2, 6, (n, 3))], 1)
        boxes[: n // 4, 0, 0] = np.round(boxes[: n // 4, 0, 0])  # ties in the sweep order
        i, j, v = overlapping_pairs(boxes, 0.5)
        assert sorted(zip(i.tolist(), j.tolist(), v.tolist(), strict=True)) == _brute_pairs(
            boxes, 0.5)
    with pytest.raises(ValueError):
        overlapping_pairs(np.zeros((2, 2, 3)), 0.0)


def test_world_boxes_of_many_equal_each_box_moved_alone() -> None:
    rng = np.random.default_rng(4)
    boxes = np.sort(rng.uniform(-2, 2, (30, 2, 3)), axis=1)
    poses = np.stack([T_from_xyyaw(*rng.uniform(-5, 5, 2), rng.uniform(-3, 3)) for _ in range(30)])
    many = world_boxes(boxes, poses)
    for box, T, got in zip(boxes, poses, many, strict=True):
        corners = np.array([[x, y, z] for x in box[:, 0] for y in box[:, 1] for z in box[:, 2]])
        moved = corners @ T[:3, :3].T + T[:3, 3]
        assert np.allclose(got, [moved.min(0), moved.max(0)], atol=1e-12)
        assert np.array_equal(world_box(box, T), got)


def _face(y: float, side: float) -> np.ndarray:
    """One face of a 10 cm partition along x (2 m high, 2 cm spacing) and a 0.3 m strip of
    floor beside it, on the `side` (+1 north, −1 south) it is seen from."""
    s = 0.02
    x = np.arange(0.0, 4.0, s)
    wall = np.stack(np.meshgrid(x, [y], np.arange(0.0, 2.0, s)), -1).reshape(-1, 3)
    strip = y + side * np.arange(s, 0.3, s)
    floor = np.stack(np.meshgrid(x, strip, [0.0]), -1).reshape(-1, 3)
    return np.concatenate([wall, floor])


def _in_frame(points_world: np.ndarray, T_world_submap: np.ndarray) -> np.ndarray:
    T = invert(T_world_submap)
    return points_world @ T[:3, :3].T + T[:3, 3]


def test_the_two_faces_of_a_partition_are_not_laid_on_each_other() -> None:
    """Robots on either side of a partition see faces 10 cm apart; GICP pairs them (the AWS
    house's west room: six registrations 10.5-11.4 cm off). The back-to-back gate rejects it;
    a robot on the same side as the target still registers."""
    T_north, T_south = T_from_xyyaw(2.0, 1.5, 0.0), T_from_xyyaw(2.0, -1.4, 0.0)
    off = RegistrationParams(sigma_m=0.05)
    gated = RegistrationParams(sigma_m=0.05, max_opposed_frac=0.15)
    target = prepare(_in_frame(_face(0.1, +1.0), T_north), off)
    across = prepare(_in_frame(_face(0.0, -1.0), T_south), off)
    T_true = invert(T_north) @ T_south
    laid = register(target, across, T_true, off)
    assert laid is not None  # the failure: the south face moved onto the north one
    assert abs((invert(T_true) @ laid.T_target_source)[1, 3] - 0.1) < 0.02
    assert opposed_fraction(target, across, laid.T_target_source, off.fine_corr_m,
                            np.asarray(off.viewpoint_m)) > 0.9
    assert register(target, across, T_true, gated) is None
    T_beside = T_from_xyyaw(2.6, 1.2, 0.2)
    same_side = prepare(_in_frame(_face(0.1, +1.0), T_beside), off)
    T_init = invert(T_north) @ T_from_xyyaw(2.63, 1.18, 0.21)
    kept = register(target, same_side, T_init, gated)
    assert kept is not None
    placed_world = T_north @ kept.T_target_source
    # across the wall (world y) it is right; along it a plain wall cannot say
    assert abs(placed_world[1, 3] - T_beside[1, 3]) < 0.01


def test_a_submaps_normals_are_computed_once_and_match_any_subsets() -> None:
    """The back-to-back gate reads each fine point's normal from one decomposition of the
    whole cloud, kept with the submap: the rows are bit for bit those of the subset's own."""
    params = RegistrationParams(sigma_m=0.05)
    prepared = prepare(_face(0.1, +1.0), params)
    viewpoint = np.asarray(params.viewpoint_m)
    points, normals, flat = prepared.fine_normals(viewpoint)
    assert prepared.fine_normals(viewpoint)[1] is normals  # kept, not recomputed
    cloud = prepared.fine[0]
    rows = np.random.default_rng(0).integers(0, len(points), 500)
    sub_normals, sub_flat = flat_normals(np.asarray(cloud.covs())[rows, :3, :3],
                                         np.asarray(cloud.points())[rows, :3], viewpoint)
    assert np.array_equal(normals[rows], sub_normals) and np.array_equal(flat[rows], sub_flat)
    assert flat.mean() > 0.8  # a wall and a floor: flat nearly everywhere
    other = prepared.fine_normals(viewpoint + 1.0)[1]
    assert other is not normals  # another viewpoint, its own normals
