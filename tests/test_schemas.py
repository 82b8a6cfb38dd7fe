"""Every message kind round-trips; every kind of bad input raises DecodeError."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest
import zstandard

from schemas import DecodeError, Keys, decode, encode
from schemas import messages as m


def _samples() -> list[m.Message]:
    rng = np.random.default_rng(0)
    pose = m.Pose2D(x=1.0, y=-2.0, yaw=0.5)
    return [
        m.Clock(tick=3, stamp_ns=300_000_000, dt_ns=100_000_000, lockstep=True, camera_tick=False),
        m.RgbdFrame(
            robot_id=1, tick=2, stamp_ns=1, depth_m=rng.random((12, 16), dtype=np.float32),
            rgb=rng.integers(0, 255, (12, 16, 3), dtype=np.uint8), K=np.eye(3),
            T_base_cam=np.eye(4), range_max_m=5.0,
        ),
        m.Odometry(robot_id=0, tick=1, stamp_ns=1, pose_odom=pose, v_mps=0.2, omega_radps=0.1),
        m.CmdVel(robot_id=0, tick=1, v_mps=0.3, omega_radps=-0.2),
        m.RobotPose(robot_id=2, tick=1, stamp_ns=5, pose_world=pose, state="goal"),
        m.Submap(
            robot_id=1, submap_id=4, seq=9, tick=1, stamp_ns=1, T_world_submap=np.eye(4),
            points_mm=rng.integers(-5000, 5000, (3, 50), dtype=np.int16),
            colors=rng.integers(0, 255, (50, 3), dtype=np.uint8),
            counts=np.ones(50, dtype=np.uint16),
            free_cells=rng.integers(-100, 100, (2, 20), dtype=np.int16), cell_m=0.05,
            offsets=rng.integers(0, 125, 50, dtype=np.uint8), offset_levels=5,
        ),
        m.Correction(robot_id=1, tick=3, submap_ids=np.arange(2, dtype=np.int32),
                     T_world_submap=np.stack([np.eye(4)] * 2)),
        m.Goal(robot_id=0, tick=1, goal_id=3, x=1.0, y=2.0, frontier_class="weak", revenue=0.5),
        m.GoalStatus(robot_id=0, tick=1, goal_id=3, status="invalid", reason="too slow"),
        m.OccupancyGrid(tick=1, resolution_m=0.05, origin_x=-1.0, origin_y=-2.0,
                        cells=np.full((10, 20), -1, dtype=np.int8)),
        m.Frontiers(
            tick=1, complete=False, assigned={0: 1},
            frontiers=[m.Frontier(frontier_id=1, frontier_class="unexplored", centroid=(1, 2, 0.5),
                                  goal_xy=(1.0, 2.0), size=4, gain=0.3, importance=0.7)],
        ),
        m.EdgeAck(tick=10),
        m.CloudRequest(robot_id=2),
        m.GridRequest(robot_id=1),
        m.Cloud(tick=1, points_world=rng.random((30, 3), dtype=np.float32),
                colors=np.zeros((30, 3), dtype=np.uint8), robot_ids=np.zeros(30, dtype=np.uint8)),
        m.Inventory(tick=4, submaps={1: [m.SubmapInfo(epoch=0, submap_id=3, voxels=120)]}),
        m.GtPose(robot_id=0, tick=1, stamp_ns=1, pose_world=pose),
    ]


def test_every_kind_has_a_sample() -> None:
    assert {type(s).KIND for s in _samples()} == set(m.MESSAGE_TYPES)


@pytest.mark.parametrize("message", _samples(), ids=lambda s: type(s).KIND)
def test_round_trip(message: m.Message) -> None:
    decoded = decode(encode(message), type(message))
    assert type(decoded) is type(message)
    for name in type(message).model_fields:
        a, b = getattr(message, name), getattr(decoded, name)
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b)
        else:
            assert a == b


def _raw(message: m.Message) -> dict:
    return msgpack.unpackb(encode(message), raw=False, strict_map_key=False)


def _pack(obj: dict) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


def test_truncated_bytes() -> None:
    payload = encode(_samples()[1])
    with pytest.raises(DecodeError, match="malformed msgpack"):
        decode(payload[: len(payload) // 2])


def test_not_a_map_and_unknown_kind() -> None:
    with pytest.raises(DecodeError, match="not a map"):
        decode(_pack([1, 2]))  # type: ignore[arg-type]
    with pytest.raises(DecodeError, match="unknown kind"):
        decode(_pack({"kind": "teleport", "v": 1}))


def test_unexpected_kind() -> None:
    with pytest.raises(DecodeError, match="unexpected kind"):
        decode(encode(m.EdgeAck(tick=1)), m.CmdVel)


def test_absurd_tick_and_stamp_are_refused() -> None:
    for field, value in (("tick", m.MAX_TICK + 1), ("tick", 2**64 - 1), ("stamp_ns", 2**63)):
        obj = _raw(m.Clock(tick=3, stamp_ns=1, dt_ns=1, lockstep=True, camera_tick=False))
        obj[field] = value
        with pytest.raises(DecodeError):
            decode(_pack(obj))
    ok = _raw(m.EdgeAck(tick=m.MAX_TICK))
    assert decode(_pack(ok)) == m.EdgeAck(tick=m.MAX_TICK)


def test_wrong_schema_version() -> None:
    obj = _raw(m.EdgeAck(tick=1))
    obj["v"] = 2
    with pytest.raises(DecodeError, match="wrong schema version"):
        decode(_pack(obj))


def test_wrong_dtype_and_shape() -> None:
    obj = _raw(_samples()[1])
    obj["K"]["dtype"] = "float32"
    with pytest.raises(DecodeError, match="invalid rgbd"):
        decode(_pack(obj))
    obj = _raw(_samples()[1])
    obj["K"]["shape"] = [9]
    with pytest.raises(DecodeError, match="invalid rgbd"):
        decode(_pack(obj))
    obj = _raw(_samples()[1])
    obj["K"]["data"] = obj["K"]["data"][:-8]
    with pytest.raises(DecodeError, match="invalid rgbd"):
        decode(_pack(obj))


def test_submap_arrays_must_agree_per_voxel() -> None:
    submap = next(s for s in _samples() if isinstance(s, m.Submap))
    for field, value in (("colors", submap.colors[:-1]), ("offsets", submap.offsets[:-1]),
                         ("offsets", np.full(50, 125, np.uint8))):  # a code ≥ 5³
        with pytest.raises(DecodeError, match="invalid submap"):
            decode(encode(submap.model_copy(update={field: value})))
    assert decode(encode(submap.model_copy(update={"offsets": np.zeros(0, np.uint8)})))


def test_nan_and_infinite_values() -> None:
    obj = _raw(m.CmdVel(robot_id=0, tick=1, v_mps=0.1, omega_radps=0.0))
    obj["v_mps"] = float("nan")
    with pytest.raises(DecodeError, match="invalid cmd_vel"):
        decode(_pack(obj))
    cloud = next(s for s in _samples() if isinstance(s, m.Cloud))
    obj = _raw(cloud)
    bad = cloud.points_world.copy()
    bad[3, 1] = np.inf
    obj["points_world"] = {"dtype": "float32", "shape": [30, 3], "data": bad.tobytes()}
    with pytest.raises(DecodeError, match="NaN or infinite"):
        decode(_pack(obj))
    with pytest.raises(ValueError):
        m.Pose2D(x=float("inf"), y=0.0, yaw=0.0)


def test_array_size_cap() -> None:
    payload = encode(_samples()[1])
    decode(payload, max_array_bytes=10_000)
    with pytest.raises(DecodeError, match="exceeds cap"):
        decode(payload, max_array_bytes=100)


def test_corrupt_compressed_array() -> None:
    obj = _raw(_samples()[1])
    obj["depth_m"]["data"] = b"\x00" * 40
    with pytest.raises(DecodeError, match="invalid rgbd"):
        decode(_pack(obj))


def test_missing_and_extra_fields() -> None:
    obj = _raw(m.EdgeAck(tick=1))
    obj["extra"] = 1
    with pytest.raises(DecodeError):
        decode(_pack(obj))
    obj = _raw(m.EdgeAck(tick=1))
    del obj["tick"]
    with pytest.raises(DecodeError):
        decode(_pack(obj))


def test_keys() -> None:
    keys = Keys("mission1")
    assert keys.rgbd(2) == "mission1/robot/2/rgbd"
    assert keys.gt_pose(0) == "mission1/eval/robot/0/gt_pose"
    assert keys.robot_id("mission1/robot/17/submap") == 17
    assert keys.alive_member(keys.alive("agent", 3)) == ("agent", "3")
    with pytest.raises(ValueError):
        Keys("bad/*")
    with pytest.raises(ValueError):
        keys.robot_id("mission1/map/grid")


def test_peek_tick_reads_the_tick_and_rejects_anything_else() -> None:
    from schemas.codec import peek_tick

    pose = m.RobotPose(robot_id=1, tick=42, stamp_ns=4_200_000_000,
                       pose_world=m.Pose2D(x=1.0, y=2.0, yaw=0.5))
    assert peek_tick(encode(pose)) == 42
    assert peek_tick(b"\xc1garbage") is None
    assert peek_tick(msgpack.packb([1, 2, 3])) is None
    assert peek_tick(msgpack.packb({"tick": -1})) is None
    assert peek_tick(msgpack.packb({"tick": True})) is None
    assert peek_tick(msgpack.packb({"kind": "pose"})) is None


def test_filtered_arrays_round_trip_bit_for_bit_and_shrink_a_submap() -> None:
    """Delta (wrapping at the type's ends) and shuffle filters decode to the very array that
    was encoded, and a submap of sorted voxels with smooth colours gets smaller on the wire."""
    rng = np.random.default_rng(1)
    n = 4000
    ends = np.array([[-32768, 32767, 0, -1], [32767, -32768, 1, 0], [5, -5, 32767, -32768]],
                    np.int16)
    points = np.sort(rng.integers(-3000, 3000, (3, n)).astype(np.int16), axis=1)
    points[:, :4] = ends
    grey = rng.integers(0, 256, n)
    colors = np.stack([grey, grey + rng.integers(-3, 4, n), grey], 1).clip(0, 255)
    colors = colors.astype(np.uint8)
    colors[:2] = [[0, 255, 0], [255, 0, 255]]
    sub = m.Submap(robot_id=1, submap_id=4, seq=9, tick=1, stamp_ns=1, T_world_submap=np.eye(4),
                   points_mm=points, colors=colors,
                   counts=rng.integers(1, 70000, n).clip(0, 65535).astype(np.uint16),
                   free_cells=rng.integers(-32768, 32767, (2, 50), dtype=np.int16), cell_m=0.05)
    raw = _raw(sub)
    assert raw["points_mm"]["f"] == "delta" and raw["counts"]["f"] == "shuffle"
    back = decode(encode(sub), m.Submap)
    for name in ("points_mm", "colors", "counts", "free_cells"):
        a, b = getattr(sub, name), getattr(back, name)
        assert a.dtype == b.dtype and np.array_equal(a, b)
    unfiltered = dict(raw)  # a sender without filters still decodes

    for name in ("points_mm", "colors", "counts", "free_cells"):
        arr = getattr(sub, name)
        unfiltered[name] = {"dtype": arr.dtype.name, "shape": list(arr.shape),
                            "data": arr.tobytes()}
    assert decode(_pack(unfiltered), m.Submap).points_mm.tobytes() == points.tobytes()
    level3 = sum(len(zstandard.ZstdCompressor(level=3).compress(getattr(sub, k).tobytes()))
                 for k in ("points_mm", "colors", "counts", "free_cells"))
    assert sum(len(raw[k]["data"]) for k in ("points_mm", "colors", "counts",
                                             "free_cells")) < 0.9 * level3


def test_unknown_or_misplaced_array_filter_is_refused() -> None:
    obj = _raw(_samples()[5])  # the submap
    obj["counts"]["f"] = "reverse"
    with pytest.raises(DecodeError, match="filter"):
        decode(_pack(obj))
    obj = _raw(_samples()[1])  # a camera frame: delta is for integers only
    obj["depth_m"]["f"] = "delta"
    with pytest.raises(DecodeError, match="filter"):
        decode(_pack(obj))


def test_submap_odometry_frame_pose_is_optional_and_checked() -> None:
    submap = next(s for s in _samples() if isinstance(s, m.Submap))
    assert decode(encode(submap), m.Submap).T_odom_submap is None  # an older agent's
    T = np.eye(4)
    T[:2, 3] = [1.5, -0.25]
    with_pose = decode(encode(submap.model_copy(update={"T_odom_submap": T})), m.Submap)
    assert np.array_equal(with_pose.T_odom_submap, T)
    obj = _raw(submap.model_copy(update={"T_odom_submap": T}))
    obj["T_odom_submap"]["shape"], obj["T_odom_submap"]["data"] = [3, 4], T[:3].tobytes()
    with pytest.raises(DecodeError):
        decode(_pack(obj))
