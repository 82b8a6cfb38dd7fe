"""Bad payloads for the bus: every one must fail `decode` with a DecodeError (no other
exception, no valid message). Built by mutating a valid message of the key's kind."""

from __future__ import annotations

import math
from typing import Any

import msgpack
import numpy as np

from schemas import encode
from schemas import messages as m

OVERSIZE_BYTES = 2 * 1024 * 1024


def templates(robot: int) -> dict[str, m.Message]:
    """A valid message per agent-published topic (the keys an agent's login reaches)."""
    rng = np.random.default_rng(robot)
    pose = m.Pose2D(x=0.5, y=0.5, yaw=0.0)
    return {
        "pose": m.RobotPose(robot_id=robot, tick=1, stamp_ns=1, pose_world=pose),
        "cmd_vel": m.CmdVel(robot_id=robot, tick=1, v_mps=0.1, omega_radps=0.0),
        "goal_status": m.GoalStatus(robot_id=robot, tick=1, goal_id=1, status="reached"),
        "submap": m.Submap(
            robot_id=robot, submap_id=1, seq=0, tick=1, stamp_ns=1, T_world_submap=np.eye(4),
            points_mm=rng.integers(-500, 500, (3, 20), dtype=np.int16),
            colors=np.zeros((20, 3), np.uint8), counts=np.ones(20, np.uint16),
            free_cells=np.zeros((2, 4), np.int16), cell_m=0.05),
    }


def _pack(obj: Any) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


def _first_array(raw: dict[str, Any]) -> str | None:
    return next((k for k, v in raw.items() if isinstance(v, dict) and "dtype" in v), None)


def _poison_float(raw: dict[str, Any], value: float) -> dict[str, Any]:
    """`raw` with `value` in its first float field, nested ones (a pose) included; `raw`
    itself when it has none."""
    for name, field in raw.items():
        if isinstance(field, float):
            return {**raw, name: value}
        if isinstance(field, dict) and "dtype" not in field:
            inner = _poison_float(field, value)
            if inner is not field:
                return {**raw, name: inner}
    return raw  # no float anywhere


def bad_payloads(template: m.Message, seed: int = 0) -> list[tuple[str, bytes]]:
    """(what, payload) pairs, each of which `decode(payload, type(template))` must reject."""
    rng = np.random.default_rng(seed)
    good = encode(template)
    raw: dict[str, Any] = msgpack.unpackb(good, raw=False)
    out = [
        ("random bytes", rng.bytes(int(rng.integers(1, 256)))),
        ("empty", b""),
        ("truncated", good[: len(good) // 2]),
        ("not a map", _pack([1, 2, 3])),
        ("wrong kind", _pack({**raw, "kind": "clock" if raw["kind"] != "clock" else "pose"})),
        ("unknown kind", _pack({**raw, "kind": "x" * 300})),
        ("wrong schema version", _pack({**raw, "v": 99})),
        ("missing field", _pack({k: v for k, v in raw.items() if k not in ("tick",)})),
        ("extra field", _pack({**raw, "evil": 1})),
        ("absurd robot id", _pack({**raw, "robot_id": 10**9})),
        ("negative tick", _pack({**raw, "tick": -5})),
        ("oversize", rng.bytes(OVERSIZE_BYTES)),
    ]
    for what, value in (("NaN", math.nan), ("inf", -math.inf)):
        poisoned = _poison_float(raw, value)
        if poisoned is not raw:  # the kind has a float field
            out.append((what, _pack(poisoned)))
    name = _first_array(raw)
    if name is not None:
        arr = raw[name]
        out += [
            ("array dtype lies", _pack({**raw, name: {**arr, "dtype": "float32"
                                                       if arr["dtype"] != "float32"
                                                       else "int8"}})),
            ("array shape lies", _pack({**raw, name: {**arr, "shape": [s + 1 for s in
                                                                       arr["shape"]]}})),
            ("array byte length lies", _pack({**raw, name: {**arr, "data": arr["data"][:-3]}})),
            ("array claims 1 TB", _pack({**raw, name: {**arr, "shape": [2**20, 2**20]}})),
            ("array NaN", _pack({**raw, name: {**arr, "dtype": "float64", "shape": [4, 4],
                                                "z": False,
                                                "data": np.full(16, np.nan).tobytes()}})),
        ]
    return out
