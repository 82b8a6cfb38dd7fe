"""The launcher's traffic count: only messages a robot's processes would accept count."""

from __future__ import annotations

from typing import Any

import msgpack

from schemas import encode
from schemas import messages as m
from schemas.keys import Keys
from services.launcher.monitor import Monitor


class _Bus:
    """Just what Monitor's constructor declares (no zenoh: `_count` is called directly)."""

    keys = Keys()

    def __getattr__(self, name: str) -> Any:
        return lambda *args, **kwargs: None


def test_bad_messages_on_a_robot_key_are_not_traffic() -> None:
    monitor = Monitor(_Bus(), robots=2)  # type: ignore[arg-type]
    keys = _Bus.keys
    pose = m.RobotPose(robot_id=0, tick=3, stamp_ns=1, pose_world=m.Pose2D(x=0.0, y=0.0, yaw=0.0))
    good = encode(pose)
    monitor._count(keys.pose(0), good, m.RobotPose)
    fuzz = [
        msgpack.packb({"tick": 1, "junk": b"x" * 5000}),  # a tick, nothing else valid
        good[: len(good) // 2],  # truncated
        encode(pose.model_copy(update={"robot_id": 1})),  # claims another robot
        encode(m.CmdVel(robot_id=0, tick=3, v_mps=0.1, omega_radps=0.0)),  # wrong kind
    ]
    for payload in fuzz:
        monitor._count(keys.pose(0), payload, m.RobotPose)
    assert monitor.bytes_per_robot() == {0: len(good), 1: 0}
    assert sum(monitor.bad_taps.values()) == len(fuzz)
