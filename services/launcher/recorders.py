"""The launcher's recordings: mission.mcap (ROS 2) and mission.rrd (rerun, also the live
view). Thin writers over the pure converters (`ros2_cdr`, `rerun_convert`): they read what
the monitor already receives (its bus messages, the coverage sampler's clouds and rows) and
publish nothing, so a lockstep mission's results do not depend on them.

`Recorders` fans each call out to every recorder under one lock (the monitor calls from the
main thread, the sampler from its own); a recorder that fails is logged, counted and left out
from then on, never the mission's failure.
"""

from __future__ import annotations

import logging
import threading
import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO, Protocol

import numpy as np
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import CompressionType, Writer

from schemas import messages as m
from services.launcher import ros2_cdr as cdr
from services.launcher import ros2_defs
from services.launcher.config import RecordConfig

if TYPE_CHECKING:
    from services.config import SpacemapConfig

log = logging.getLogger(__name__)

MCAP_NAME, RRD_NAME = "mission.mcap", "mission.rrd"


class Sink(Protocol):
    """What the monitor and the sampler hand a recorder."""

    def on_message(self, msg: m.Message) -> None: ...
    def on_sample(self, row: dict[str, Any], cloud: m.Cloud) -> None: ...
    def finish(self, cloud: m.Cloud, robot_points: Sequence[np.ndarray],
               grid: m.OccupancyGrid | None, tracks: dict[int, Any]) -> None: ...
    def close(self) -> None: ...


class Throttle:
    """Lets one event through per `every_s` of sim time (0: every event)."""

    def __init__(self, every_s: float) -> None:
        self.every_s, self.next_s = every_s, 0.0

    def due(self, t_s: float) -> bool:
        if t_s + 1e-9 < self.next_s:
            return False
        self.next_s = t_s + self.every_s
        return True


class McapRecorder:
    """mission.mcap, ROS 2 profile, CDR: /map_cloud and /robot_{i}/map_cloud
    (sensor_msgs/PointCloud2), /map (nav_msgs/OccupancyGrid), /robot_{i}/odom (estimate) and
    /robot_{i}/ground_truth (nav_msgs/Odometry), /tf (tf2_msgs/TFMessage: map →
    robot_{i}/base_link), /frontiers (visualization_msgs/MarkerArray). Log times are sim
    time."""

    def __init__(self, path: Path, robots: int, cfg: RecordConfig, tick_s: float) -> None:
        self.tick_ns = round(tick_s * 1e9)
        self.robots = robots
        self._file: BinaryIO = path.open("wb")
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library="spacemap")
        self._schemas = {t: self._writer.register_schema(
            name=t, encoding=SchemaEncoding.ROS2,
            data=ros2_defs.schema_text(ros2_defs.short(t)).encode()) for t in ros2_defs.TYPES}
        self._channels: dict[str, int] = {}
        self._seq = 0
        self.cloud_every, self.grid_every = Throttle(cfg.cloud_every_s), Throttle(cfg.grid_every_s)
        self.robot_xy: dict[int, tuple[float, float]] = {}
        self.cloud_tick = -1  # tick of the last merged cloud written

    def write(self, topic: str, datatype: str, stamp_ns: int, data: bytes) -> None:
        channel = self._channels.get(topic)
        if channel is None:
            channel = self._writer.register_channel(
                topic=topic, message_encoding=MessageEncoding.CDR,
                schema_id=self._schemas[datatype])
            self._channels[topic] = channel
        self._seq += 1
        self._writer.add_message(channel_id=channel, log_time=stamp_ns, publish_time=stamp_ns,
                                 sequence=self._seq, data=data)

    def on_message(self, msg: m.Message) -> None:
        if isinstance(msg, m.RobotPose):
            self.robot_xy[msg.robot_id] = (msg.pose_world.x, msg.pose_world.y)
            self.write(f"/robot_{msg.robot_id}/odom", "nav_msgs/msg/Odometry", msg.stamp_ns,
                       cdr.odometry(msg.robot_id, msg.pose_world, msg.stamp_ns))
            self.write("/tf", "tf2_msgs/msg/TFMessage", msg.stamp_ns, cdr.tf_message(
                [(cdr.base_frame(msg.robot_id), msg.pose_world)], msg.stamp_ns))
        elif isinstance(msg, m.GtPose):
            self.write(f"/robot_{msg.robot_id}/ground_truth", "nav_msgs/msg/Odometry",
                       msg.stamp_ns, cdr.odometry(msg.robot_id, msg.pose_world, msg.stamp_ns,
                                                  f"robot_{msg.robot_id}/ground_truth"))
        elif isinstance(msg, m.OccupancyGrid):
            if self.grid_every.due(msg.tick * self.tick_ns * 1e-9):
                self._grid(msg)
        elif isinstance(msg, m.Frontiers):
            stamp = msg.tick * self.tick_ns
            self.write("/frontiers", "visualization_msgs/msg/MarkerArray", stamp,
                       cdr.frontier_markers(msg, self.robot_xy, stamp))

    def _grid(self, grid: m.OccupancyGrid) -> None:
        stamp = grid.tick * self.tick_ns
        self.write("/map", "nav_msgs/msg/OccupancyGrid", stamp, cdr.occupancy_grid(grid, stamp))

    def _cloud(self, topic: str, points: np.ndarray, colors: np.ndarray | None,
               tick: int) -> None:
        stamp = tick * self.tick_ns
        self.write(topic, "sensor_msgs/msg/PointCloud2", stamp,
                   cdr.point_cloud2(points, colors, stamp))

    def on_sample(self, row: dict[str, Any], cloud: m.Cloud) -> None:
        if self.cloud_every.due(cloud.tick * self.tick_ns * 1e-9):
            self._cloud("/map_cloud", cloud.points_world, cloud.colors, cloud.tick)
            self.cloud_tick = cloud.tick

    def finish(self, cloud: m.Cloud, robot_points: Sequence[np.ndarray],
               grid: m.OccupancyGrid | None, tracks: dict[int, Any]) -> None:
        """The final maps: what the run folder's PLY and PGM files hold."""
        if cloud.tick != self.cloud_tick:  # not already written as the last sample
            self._cloud("/map_cloud", cloud.points_world, cloud.colors, cloud.tick)
        for robot, points in enumerate(robot_points):
            self._cloud(f"/robot_{robot}/map_cloud", points, None, cloud.tick)
        if grid is not None:
            self._grid(grid)

    def close(self) -> None:
        self._writer.finish()
        self._file.close()


class Recorders:
    """Every recorder of a run behind one lock; failures isolated (see module doc)."""

    def __init__(self, recorders: Sequence[Sink]) -> None:
        self.recorders = list(recorders)
        self.failures = 0
        self._lock = threading.Lock()

    def _each(self, what: str, *args: Any) -> None:
        with self._lock:
            for rec in list(self.recorders):
                try:
                    getattr(rec, what)(*args)
                except Exception:  # a recording must never end the mission
                    self.failures += 1
                    self.recorders.remove(rec)
                    log.exception("%s failed in %s; it records nothing more",
                                  type(rec).__name__, what)

    def on_message(self, msg: m.Message) -> None:
        self._each("on_message", msg)

    def on_sample(self, row: dict[str, Any], cloud: m.Cloud) -> None:
        self._each("on_sample", row, cloud)

    def finish(self, cloud: m.Cloud, robot_points: Sequence[np.ndarray],
               grid: m.OccupancyGrid | None, tracks: dict[int, Any]) -> None:
        self._each("finish", cloud, robot_points, grid, tracks)

    def close(self) -> None:
        self._each("close")
        self.recorders.clear()


def camera_ticks(config: SpacemapConfig) -> int:
    """Ticks between the camera frames the live view shows (`record.camera_every_s`, in
    whole camera periods)."""
    cam = config.sim.camera_every_ticks
    every = max(1, round(config.record.camera_every_s / (config.sim.tick_s * cam)))
    return every * cam


def open_recorders(out_dir: Path | None, robots: int, cfg: RecordConfig, tick_s: float,
                   tracks: dict[int, Any], view: str | None = None) -> Recorders:
    """The recorders `cfg` asks for in `out_dir` (None: none written), and the live view
    (`view`: "spawn", "serve[:PORT]" or a rerun+http:// URL; None: no live view); `tracks`:
    the monitor's, which the rerun trajectories are drawn from."""
    recs: list[Sink] = []
    if out_dir is not None and cfg.mcap:
        recs.append(McapRecorder(out_dir / MCAP_NAME, robots, cfg, tick_s))
    rrd = out_dir / RRD_NAME if out_dir is not None and cfg.rrd else None
    if rrd is not None or view is not None:
        from services.launcher.rerun_recorder import RerunRecorder

        recs.append(RerunRecorder(rrd, robots, cfg, tick_s, view, str(uuid.uuid4()), tracks))
    return Recorders(recs)
