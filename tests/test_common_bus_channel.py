"""Messages read from zenoh's own queue (`Bus.subscribe(channel=True)`): never after a later
waking message, validated like the rest, read when nothing wakes the reader too."""

from __future__ import annotations

import time

import zenoh

from schemas.messages import Clock, Pose2D, RobotPose
from services.common.bus import Bus, BusConfig, Inbound, zenoh_config


def _pose(robot: int, tick: int) -> RobotPose:
    return RobotPose(robot_id=robot, tick=tick, stamp_ns=tick,
                     pose_world=Pose2D(x=float(tick), y=0.0, yaw=0.0))


def _poll_all(bus: Bus, n: int, deadline_s: float = 5.0) -> list[object]:
    got: list[object] = []
    end = time.monotonic() + deadline_s
    while len(got) < n and time.monotonic() < end:
        item = bus.poll(timeout=0.05)
        if isinstance(item, Inbound):
            got.append(item.message)
    return got


def test_channel_messages_come_before_the_waking_message_after_them() -> None:
    with zenoh.open(zenoh_config("peer", listen=[])) as session:
        bus = Bus(session, BusConfig())
        bus.subscribe(bus.keys.any_robot("pose"), RobotPose, channel=True)
        bus.subscribe(bus.keys.clock(), Clock)
        for tick in range(5):
            bus.publish(bus.keys.pose(tick % 2), _pose(tick % 2, tick))
        bus.publish(bus.keys.clock(), Clock(tick=5, stamp_ns=5, dt_ns=1, lockstep=True,
                                                  camera_tick=False))
        got = _poll_all(bus, 6)
        assert [type(m).__name__ for m in got] == ["RobotPose"] * 5 + ["Clock"]
        assert [m.tick for m in got[:5]] == list(range(5))  # each key's order kept
        # with nothing that wakes the reader, they are read at its timeout
        for tick in (6, 7):
            bus.publish(bus.keys.pose(1), _pose(1, tick))
        assert [m.tick for m in _poll_all(bus, 2)] == [6, 7]
        bus.close()


def test_channel_messages_are_validated_and_bad_ones_counted() -> None:
    with zenoh.open(zenoh_config("peer", listen=[])) as session:
        bus = Bus(session, BusConfig())
        bus.subscribe(bus.keys.any_robot("pose"), RobotPose, channel=True)
        session.put(bus.keys.pose(3), b"\x93not a pose")
        bus.publish(bus.keys.pose(3), _pose(3, 1))
        got = _poll_all(bus, 1)
        assert [m.tick for m in got] == [1] and bus.dropped.total() == 1
        session.put(bus.keys.pose(3), b"")  # never polled: close still counts it
        bus.close()
        assert bus.dropped.total() == 2
