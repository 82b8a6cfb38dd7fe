"""Keyframe submaps: delta quantization, resend rules, seq numbering and keyframe switching."""

from __future__ import annotations

import numpy as np

from services.common import voxels
from services.common.geometry import T_from_xyyaw
from services.robot_agent.config import AgentConfig
from services.robot_agent.local_map import KeyframeMapper, VoxelSubmap, decode_points_m

CFG = AgentConfig()


def _cloud(n: int = 2000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.uniform(-4, 4, (n, 3)), rng.integers(0, 256, (n, 3)).astype(np.uint8)


def test_delta_sends_centres_and_where_each_mean_lies() -> None:
    pts, cols = _cloud()
    sub = VoxelSubmap(0, np.eye(4), 0)
    sub.add_points(pts, cols, CFG.voxel_m)
    delta = sub.take_delta(CFG.voxel_m, CFG.color_resend, CFG.mean_levels)
    assert delta is not None and delta.points_mm.dtype == np.int16
    assert delta.points_mm.shape == (3, len(sub)) and delta.offsets.shape == (len(sub),)
    back = decode_points_m(delta.points_mm)
    keys = voxels.pack(voxels.voxel_indices(pts, CFG.voxel_m))
    uniq, inverse = np.unique(keys, return_inverse=True)
    # the centres, within 1 mm, one per voxel
    np.testing.assert_allclose(np.sort(back, axis=0),
                               np.sort(voxels.centres(voxels.unpack(uniq), CFG.voxel_m), axis=0),
                               atol=1e-3)
    # the decoded means: each within half a cell of its voxel's mean
    indices = voxels.voxel_indices(back, CFG.voxel_m)
    decoded = voxels.offset_points(indices, delta.offsets, CFG.voxel_m, CFG.mean_levels)
    means = np.stack([np.bincount(inverse, weights=pts[:, d]) for d in range(3)], 1)
    means /= np.bincount(inverse)[:, None]
    order = np.argsort(voxels.pack(indices))
    cell = CFG.voxel_m / CFG.mean_levels
    assert np.abs(decoded[order] - means).max() <= cell / 2 + 1e-9
    assert int(delta.counts.sum()) == len(pts)
    centres_only = VoxelSubmap(0, np.eye(4), 0)
    centres_only.add_points(pts, cols, CFG.voxel_m)
    assert centres_only.take_delta(CFG.voxel_m, CFG.color_resend, 1).offsets.size == 0


def test_only_new_or_changed_voxels_are_resent() -> None:
    pts, cols = _cloud(500)
    sub = VoxelSubmap(0, np.eye(4), 0)
    sub.add_points(pts, cols, CFG.voxel_m)
    assert sub.take_delta(CFG.voxel_m, CFG.color_resend) is not None
    assert sub.take_delta(CFG.voxel_m, CFG.color_resend) is None  # nothing changed
    sub.add_points(pts[:1], cols[:1], CFG.voxel_m)  # count 1 → 2: a power of two
    delta = sub.take_delta(CFG.voxel_m, CFG.color_resend)
    assert delta is not None and delta.points_mm.shape[1] == 1 and delta.counts[0] == 2
    sub.add_points(pts[:1], cols[:1], CFG.voxel_m)  # 3: not resent
    assert sub.take_delta(CFG.voxel_m, CFG.color_resend) is None


def test_free_cells_sent_once() -> None:
    sub = VoxelSubmap(0, np.eye(4), 0)
    sub.add_free(np.array([[0.01, 0.01], [0.02, 0.03], [-0.07, 0.12]]), 0.05)
    delta = sub.take_delta(CFG.voxel_m, CFG.color_resend)
    assert delta is not None
    assert sorted(map(tuple, delta.free_cells.T.tolist())) == [(-2, 2), (0, 0)]
    sub.add_free(np.array([[0.01, 0.01]]), 0.05)
    assert sub.take_delta(CFG.voxel_m, CFG.color_resend) is None


def test_keyframe_switches_on_distance_turn_and_age() -> None:
    cfg = AgentConfig(keyframe_dist_m=1.0, keyframe_yaw_rad=0.5, keyframe_max_ticks=50)
    mapper = KeyframeMapper(cfg)
    assert mapper.needs_keyframe(np.eye(4), 0)
    first = mapper.start_keyframe(T_from_xyyaw(1.0, 1.0, 0.0), 0)
    assert first.submap_id == 0
    assert not mapper.needs_keyframe(T_from_xyyaw(1.5, 1.0, 0.3), 10)
    assert mapper.needs_keyframe(T_from_xyyaw(2.1, 1.0, 0.0), 10)
    assert mapper.needs_keyframe(T_from_xyyaw(1.0, 1.0, -0.6), 10)
    assert mapper.needs_keyframe(T_from_xyyaw(1.0, 1.0, 0.0), 50)
    assert mapper.start_keyframe(T_from_xyyaw(2.1, 1.0, 0.0), 10).submap_id == 1


def test_frames_added_one_by_one_equal_one_batch() -> None:
    """Growing the sorted voxel arrays frame by frame (new voxels inserted in place) keeps
    them sorted and sums each voxel as one batch of the same points would."""
    rng = np.random.default_rng(3)
    frames = [rng.uniform(-2.0, 2.0, (400, 3)) + rng.uniform(-1, 1, 3) for _ in range(12)]
    colors = [rng.integers(0, 256, (400, 3)).astype(np.uint8) for _ in frames]
    incremental, batch = VoxelSubmap(0, np.eye(4), 0), VoxelSubmap(0, np.eye(4), 0)
    for pts, col in zip(frames, colors, strict=True):
        incremental.add_points(pts, col, 0.05)
    batch.add_points(np.concatenate(frames), np.concatenate(colors), 0.05)
    assert np.all(np.diff(incremental.keys) > 0)
    assert np.array_equal(incremental.keys, batch.keys)
    assert np.array_equal(incremental.counts, batch.counts)
    assert np.allclose(incremental.point_sum, batch.point_sum)
    assert np.allclose(incremental.color_sum, batch.color_sum)
    assert incremental.sent_counts.shape == incremental.keys.shape


def test_points_beyond_the_int16_range_are_dropped() -> None:
    sub = VoxelSubmap(0, np.eye(4), 0)
    pts = np.array([[1.0, 0.0, 0.5], [40.0, 0.0, 0.5], [0.0, -33.0, 0.2]])
    sub.add_points(pts, np.zeros((3, 3), np.uint8), 0.05)
    assert len(sub) == 1 and sub.counts.tolist() == [1]
