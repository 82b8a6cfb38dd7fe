"""mission.rrd and the live rerun view: one rerun recording stream whose sinks are the run
folder's file and, with a live view, a spawned viewer, a gRPC server or a remote viewer.

Timelines: `sim_time` (duration, s) and `tick` (sequence); the file and the live view both
get the default layout `rerun_convert.blueprint`. The converters are in
`rerun_convert` (pure); this class keeps only throttles and the last robot positions.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from schemas import messages as m
from services.launcher import rerun_convert as rc
from services.launcher.config import RecordConfig, parse_view
from services.launcher.recorders import Throttle

log = logging.getLogger(__name__)

POSE_BATCH = 10  # poses per robot sent together (1 s of sim time at the defaults)


def view_sinks(view: str) -> list[Any]:
    """The rerun sinks of a live view (`config.parse_view`)."""
    mode, target = parse_view(view)
    if mode == "serve":
        sink = rr.GrpcServerSink(port=int(target))
        log.info("live view served: rerun %s", sink.uri)
        return [sink]
    if mode == "spawn":  # the viewer installed beside this interpreter, else PATH's
        beside = Path(sys.executable).parent / "rerun"
        rr.spawn(port=int(target), connect=False,
                 executable_path=str(beside) if beside.exists() else None)
        return [rr.GrpcSink(f"rerun+http://127.0.0.1:{target}/proxy")]
    return [rr.GrpcSink(str(target))]


class RerunRecorder:
    """Logs the mission's entities (`rerun_convert`) to mission.rrd and/or a live viewer."""

    def __init__(self, path: Path | None, robots: int, cfg: RecordConfig, tick_s: float,
                 view: str | None, recording_id: str, tracks: dict[int, Any]) -> None:
        self.cfg, self.tick_s, self.robots = cfg, tick_s, robots
        self.tracks = tracks  # the monitor's RobotTrack per robot: estimate and truth so far
        self.rec = rr.RecordingStream("spacemap", recording_id=recording_id)
        sinks: list[Any] = [rr.FileSink(path)] if path is not None else []
        if view is not None:
            sinks += view_sinks(view)
        # the layout (`rerun_convert.blueprint`) goes with the data to every sink, so
        # `rerun mission.rrd` opens on the map, grid and curves rather than rerun's guess
        self.rec.set_sinks(*sinks, default_blueprint=rc.blueprint(robots))
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        for robot in range(robots):
            self._log(rc.robot_body(robot), static=True)
        self.grid_every, self.cloud_every = Throttle(cfg.grid_every_s), Throttle(cfg.cloud_every_s)
        self.traj_every = Throttle(cfg.trajectory_every_s)
        self.robot_xy: dict[int, tuple[float, float]] = {}
        self.cloud_tick = -1  # tick of the last merged cloud logged
        # poses waiting to go out as one column batch per robot: (tick, (x, y, yaw))
        self.pending: dict[int, list[tuple[int, tuple[float, float, float]]]] = {}
        self.grid: m.OccupancyGrid | None = None

    def _at(self, tick: int) -> None:
        self.rec.set_time("tick", sequence=tick)
        self.rec.set_time("sim_time", duration=tick * self.tick_s)

    def _log(self, entities: list[rc.Entity], static: bool = False) -> None:
        for path, archetype in entities:
            self.rec.log(path, archetype, static=static)

    def on_message(self, msg: m.Message) -> None:
        tick = getattr(msg, "tick", None)
        if tick is None:
            return
        if isinstance(msg, m.RobotPose):  # in columns, with their own times
            self._pose(msg)
            return
        self._at(tick)
        if isinstance(msg, m.OccupancyGrid):
            self.grid = msg
            if self.grid_every.due(tick * self.tick_s):
                self._log(rc.grid_image(msg))
        elif isinstance(msg, m.Frontiers):
            self._log(rc.frontiers(msg, self.robot_xy, self.grid))
        elif isinstance(msg, m.Goal | m.GoalStatus):
            self._log(rc.event(msg.robot_id, msg))
        elif isinstance(msg, m.RgbdFrame):  # the monitor reads only those due
            self._log(rc.camera(msg))

    def _pose(self, msg: m.RobotPose) -> None:
        p = msg.pose_world
        self.robot_xy[msg.robot_id] = (p.x, p.y)
        batch = self.pending.setdefault(msg.robot_id, [])
        batch.append((msg.tick, (p.x, p.y, p.yaw)))
        if len(batch) >= POSE_BATCH:
            self._send_poses(msg.robot_id)
        if self.traj_every.due(msg.tick * self.tick_s):
            self._at(msg.tick)
            self._trajectories()

    def _send_poses(self, robot: int) -> None:
        batch = self.pending.pop(robot, [])
        if batch:
            path, indexes, columns = rc.robot_poses(
                robot, [t for t, _ in batch], [p for _, p in batch], self.tick_s)
            self.rec.send_columns(path, indexes=indexes, columns=columns)

    def _trajectories(self, step: int = 5) -> None:
        for robot, track in self.tracks.items():
            self._log(rc.trajectory(robot, track.est_xyyaw, "estimate", step))
            self._log(rc.trajectory(robot, track.gt_xyyaw, "ground_truth", step))

    def on_sample(self, row: dict[str, Any], cloud: m.Cloud) -> None:
        self._at(cloud.tick)
        self._log(rc.series(row))
        if self.cloud_every.due(cloud.tick * self.tick_s):
            self._log(rc.merged_cloud(cloud, self.cfg.cloud_colors))
            self.cloud_tick = cloud.tick

    def finish(self, cloud: m.Cloud, robot_points: Sequence[np.ndarray],
               grid: m.OccupancyGrid | None, tracks: dict[int, Any]) -> None:
        """The final map, grid and whole trajectories (the run folder's), at the last tick."""
        for robot in list(self.pending):
            self._send_poses(robot)
        self._at(cloud.tick)
        if cloud.tick != self.cloud_tick:  # not already logged as the last sample
            self._log(rc.merged_cloud(cloud, self.cfg.cloud_colors))
        if grid is not None:
            self._log(rc.grid_image(grid))
        for robot, track in tracks.items():
            self._log(rc.trajectory(robot, track.est_xyyaw, "estimate"))
            self._log(rc.trajectory(robot, track.gt_xyyaw, "ground_truth"))

    def close(self) -> None:
        for robot in list(self.pending):
            self._send_poses(robot)
        self.rec.flush()
        self.rec.disconnect()
