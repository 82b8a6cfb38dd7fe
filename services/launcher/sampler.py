"""Live queries of the edge's maps: per-robot clouds and grids, and a coverage time series
sampled every few sim seconds on a background thread: coverage, BV and ghost volume from the
merged cloud, 3D overlap from each robot's own map, with metrics.json's formulas. The sampler
asks the edge for what changed in each map since its last sample (`CloudRequest.
since_version`: voxels added or whose point moved, or the whole map after a rebuild) and
scores only that (`LiveQuality.apply`), so its figures equal `map_quality`'s at a fraction of
the CPU the mission shares; it keeps a copy of the merged map for the recorders.

In lockstep the simulator does not wait for the launcher, so a sample is stamped with the
tick the edge had reached when it answered (Cloud.tick), not the tick that was asked for.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from schemas import messages as m
from schemas.codec import DecodeError
from services.common.bus import Bus
from services.evaluator.incremental import LiveQuality, MapChange, keyed_ids
from services.evaluator.scoring import Probe, map_quality
from services.launcher.monitor import Monitor

log = logging.getLogger(__name__)

SAMPLE_TIMEOUT_S = 10.0
FINAL_TIMEOUT_S = 30.0


def fetch_cloud(bus: Bus, robot_id: int = -1, timeout: float = FINAL_TIMEOUT_S) -> m.Cloud | None:
    """The merged cloud P* (robot_id -1) or one robot's own map; None when no reply."""
    try:
        reply = bus.query(bus.keys.map_cloud(), m.CloudRequest(robot_id=robot_id), m.Cloud,
                          timeout=timeout)
    except (TimeoutError, DecodeError) as exc:
        log.warning("map/cloud robot_id=%d: no usable reply (%s)", robot_id, exc)
        return None
    assert isinstance(reply, m.Cloud)
    return reply


def fetch_robot_grid(bus: Bus, robot_id: int, timeout: float = 5.0) -> m.OccupancyGrid | None:
    """One robot's own occupancy grid from `map/robot_grid`; None when no reply."""
    try:
        reply = bus.query(bus.keys.map_robot_grid(), m.GridRequest(robot_id=robot_id),
                          m.OccupancyGrid, timeout=timeout)
    except (TimeoutError, DecodeError) as exc:
        log.warning("map/robot_grid robot_id=%d: no usable reply (%s); overlap_2d_pct will be "
                    "null", robot_id, exc)
        return None
    assert isinstance(reply, m.OccupancyGrid)
    return reply


OWN_MAPS, SPLIT_MAPS = "edge per-robot map", "merged map split by robot_ids"


def robot_clouds(
    bus: Bus, merged: m.Cloud, robots: int, timeout: float = FINAL_TIMEOUT_S
) -> tuple[list[np.ndarray], str]:
    """Each robot's own map; where the edge answers with something else (an older edge
    ignores CloudRequest.robot_id), the merged map's points tagged with that robot (a voxel
    seen by several robots then counts for its first observer only: less overlap)."""
    out, sources = [], set()
    for robot in range(robots):
        reply = fetch_cloud(bus, robot, timeout)
        if reply is not None and reply.robot_id == robot:
            out.append(reply.points_world.astype(np.float64))
            sources.add(OWN_MAPS)
        else:
            out.append(merged.points_world[merged.robot_ids == robot].astype(np.float64))
            sources.add(SPLIT_MAPS)
    return out, " + ".join(sorted(sources))


def series_row(probe: Probe, cloud: m.Cloud, quality: dict[str, float | None] | None,
               grid: m.OccupancyGrid | None, tick_s: float, frontiers: int,
               robot_points: Sequence[np.ndarray] = ()) -> dict[str, Any]:
    """One time-series row: the merged cloud's figures and the robots' own maps' overlap, as
    `quality` gives them (None: `map_quality` of the cloud and `robot_points`, from scratch,
    as metrics.json)."""
    pts = cloud.points_world
    if quality is None:
        quality = map_quality(probe, pts.astype(np.float64), robot_points)
    known = int((grid.cells >= 0).sum()) if grid is not None else 0
    return {
        "sim_time_s": round(cloud.tick * tick_s, 6),
        "coverage_3d_pct": quality["coverage_3d_pct"],
        "coverage_2d_pct": probe.coverage_2d(grid),
        "overlap_3d_pct": quality["overlap_3d_pct"],
        "bounding_volume_pct": quality["bounding_volume_pct"],
        "ghost_volume_m3": quality["ghost_volume_m3"],
        "known_area_m2": known * grid.resolution_m**2 if grid is not None else 0.0,
        "frontiers": frontiers,
        "map_points": len(pts),
    }


class CloudMirror:
    """The sampler's copy of one edge map, kept by the edge's answers: whole ones replace it,
    delta ones overwrite the voxels they carry in place or append new ones. Its points are
    in the order the voxels arrived, not by key: a sorted index of keys to rows finds them,
    so a sample costs what changed plus one insert of the new keys into that index."""

    def __init__(self) -> None:
        self.keys = np.zeros(0, np.int64)  # sorted voxel keys held
        self.rows = np.zeros(0, np.int64)  # their rows, in key order
        self.size = 0
        self.points = np.zeros((0, 3), np.float32)
        self.colors = np.zeros((0, 3), np.uint8)
        self.robot_ids = np.zeros(0, np.uint8)
        self.cloud = m.Cloud(tick=0, points_world=self.points, colors=self.colors,
                             robot_ids=self.robot_ids)

    def apply(self, reply: m.Cloud) -> m.Cloud:
        """The whole map after `reply` (a validated Cloud), its points in arrival order."""
        if not reply.delta:
            self.size = 0
            self.keys = self.rows = np.zeros(0, np.int64)
            if reply.voxel_keys.size != len(reply.points_world):  # an edge that sends no keys
                self.cloud = reply
                return reply
        keys = reply.voxel_keys
        pos = np.searchsorted(self.keys, keys)
        held = pos < self.keys.size
        held[held] = self.keys[pos[held]] == keys[held]
        rows = np.empty(keys.size, np.int64)
        rows[held] = self.rows[pos[held]]
        rows[~held] = self.size + np.arange(np.count_nonzero(~held))
        self._reserve(self.size + rows.size - np.count_nonzero(held))
        self.points[rows] = reply.points_world
        self.colors[rows] = reply.colors
        self.robot_ids[rows] = reply.robot_ids
        self.size += rows.size - np.count_nonzero(held)
        self.keys = np.insert(self.keys, pos[~held], keys[~held])
        self.rows = np.insert(self.rows, pos[~held], rows[~held])
        self.cloud = m.Cloud(tick=reply.tick, robot_id=reply.robot_id,
                             points_world=self.points[:self.size],
                             colors=self.colors[:self.size],
                             robot_ids=self.robot_ids[:self.size], version=reply.version)
        return self.cloud

    def _reserve(self, rows: int) -> None:
        """Room for `rows` rows (doubling): the arrays a cloud handed out stay as they were."""
        if rows <= self.points.shape[0]:
            return
        capacity = max(1024, 2 * rows)
        for name in ("points", "colors", "robot_ids"):
            old = getattr(self, name)
            grown = np.zeros((capacity, *old.shape[1:]), old.dtype)
            grown[:self.size] = old[:self.size]
            setattr(self, name, grown)


class SampleSink(Protocol):
    """A reader of each time-series row and the merged cloud it was scored on. The cloud's
    arrays are the sampler's copy of the map (`CloudMirror`), changed in place by the next
    sample: a sink copies what it keeps."""

    def on_sample(self, row: dict[str, Any], cloud: m.Cloud) -> None: ...


class CoverageSampler:
    """Samples the merged map and the robots' own maps every `every_s` sim seconds on its
    own thread."""

    def __init__(self, monitor: Monitor, probe: Probe, every_s: float, tick_s: float) -> None:
        self.monitor, self.probe, self.every_s, self.tick_s = monitor, probe, every_s, tick_s
        self.rows: list[dict[str, Any]] = []
        self.sinks: list[SampleSink] = []
        # built by the sampling thread's first sample: a mission sampled only at its end
        # scores the final map from scratch and needs neither its truth index nor, before the
        # services start, the probe's trees (1.2 CPU-s in the AWS house)
        self._quality: LiveQuality | None = None
        self.merged = CloudMirror()
        self.versions: dict[int, int] = {}  # per map (-1 merged): the edge version held
        self.cpu_s = 0.0  # the sampling thread's own CPU time (profile.json: `sampler_cpu_s`)
        # its parts: the edge's answers (with the mirror), the tallies, the row (2D coverage),
        # the recorders' writing (profile.json: `sampler_stage_cpu_s`)
        self.stage_cpu_s = dict.fromkeys(("fetch", "score", "row", "record"), 0.0)
        self._rows_lock = threading.Lock()  # the final map is added from the main thread
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="coverage-sampler", daemon=True)

    def start(self) -> None:
        if self.every_s > 0:
            self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():  # a sample makes 1 + robots queries
            self._thread.join(timeout=SAMPLE_TIMEOUT_S * (1 + self.monitor.robots) + 30.0)

    def _loop(self) -> None:
        due = self.every_s
        start = time.thread_time()
        while not self._stop.wait(0.05):
            self.cpu_s = time.thread_time() - start
            if self.monitor.sim_time_s < due:
                continue
            self.sample()
            due = (np.floor(self.monitor.sim_time_s / self.every_s) + 1) * self.every_s
        self.cpu_s = time.thread_time() - start
        log.info("coverage sampler: %d rows, %.2f CPU-s", len(self.rows), self.cpu_s)

    def sample(self) -> None:
        """Ask for what changed in the merged map, then in each robot's own map, and add a
        row. The robot maps may be a tick or two newer than the merged one (separate
        queries)."""
        start = time.thread_time()
        reply = self._fetch(-1)
        if reply is None:
            return
        cloud = self.merged.apply(reply)
        changes = [self._change(-1, reply)]
        for robot in range(self.monitor.robots):
            own = self._fetch(robot)
            if own is not None and own.robot_id == robot:
                changes.append(self._change(robot, own))
            else:  # an older edge: the merged map's points this robot observed first
                self.versions.pop(robot, None)
                pts = cloud.points_world[cloud.robot_ids == robot].astype(np.float64)
                changes.append(MapChange(pts))
        self._await_edge_tick(cloud.tick)
        fetched = time.thread_time()
        self.stage_cpu_s["fetch"] += fetched - start
        if self._quality is None:
            self._quality = LiveQuality(self.probe)
        quality = self._quality.apply(changes[0], changes[1:])
        self.stage_cpu_s["score"] += time.thread_time() - fetched
        if quality is None:
            log.warning("sample at tick %d: a map could not be updated; whole maps next time",
                        cloud.tick)
            self.versions.clear()
            return
        self._add_row(cloud, quality)

    def _fetch(self, robot_id: int) -> m.Cloud | None:
        """The edge's answer for one map since the version held (whole the first time)."""
        request = m.CloudRequest(robot_id=robot_id,
                                 since_version=self.versions.get(robot_id, -1))
        try:
            reply = self.monitor.bus.query(self.monitor.bus.keys.map_cloud(), request, m.Cloud,
                                           timeout=SAMPLE_TIMEOUT_S)
        except (TimeoutError, DecodeError) as exc:
            log.warning("map/cloud robot_id=%d: no usable reply (%s)", robot_id, exc)
            return None
        assert isinstance(reply, m.Cloud)
        return reply

    def _change(self, robot_id: int, reply: m.Cloud) -> MapChange:
        """What a sample scores of one reply: keyed (and maybe a delta), or, from an edge
        that sends no keys, the whole map by coordinates."""
        pts = reply.points_world.astype(np.float64)
        if reply.voxel_keys.size != len(pts):
            self.versions.pop(robot_id, None)
            return MapChange(pts)
        self.versions[robot_id] = reply.version
        return MapChange(pts, keyed_ids(reply.voxel_keys), whole=not reply.delta)

    def _await_edge_tick(self, tick: int, timeout_s: float = 2.0) -> None:
        """The edge publishes its grid of tick k before it can answer with Cloud(tick=k), but
        the monitor may not have read it yet: give it a moment, then use the latest grid.
        Once stopped (the final map, added from the main thread after `_catch_up`), no wait."""
        deadline = time.monotonic() + timeout_s
        pause = threading.Event()
        while (not self._stop.is_set() and tick not in self.monitor.recent_grids
               and time.monotonic() < deadline):
            pause.wait(0.02)  # the main thread pumps the monitor meanwhile

    def add(self, cloud: m.Cloud, robot_points: Sequence[np.ndarray]) -> None:
        """Add a sample of whole maps (the final map, with the robot maps the run folder
        keeps, so the last row's overlap is metrics.json's); keeps rows in sim-time order.
        Scored from scratch: the tallies know the live maps by key, these by coordinates,
        and re-adding every point through them costs more than `map_quality`."""
        self._await_edge_tick(cloud.tick)
        quality = map_quality(self.probe, cloud.points_world.astype(np.float64), robot_points)
        self._add_row(cloud, quality)

    def _add_row(self, cloud: m.Cloud, quality: dict[str, float | None]) -> None:
        mine = threading.current_thread() is self._thread  # stages count this thread's CPU
        start = time.thread_time()
        grid, frontiers = self.monitor.at_tick(cloud.tick)
        row = series_row(self.probe, cloud, quality, grid, self.tick_s, frontiers)
        with self._rows_lock:
            if self.rows and row["sim_time_s"] < self.rows[-1]["sim_time_s"]:
                return
            if self.rows and row["sim_time_s"] == self.rows[-1]["sim_time_s"]:
                self.rows.pop()  # the same edge tick answered twice: keep the newer view
            self.rows.append(row)
            made = time.thread_time()
            for sink in self.sinks:
                sink.on_sample(row, cloud)
        if mine:
            self.stage_cpu_s["row"] += made - start
            self.stage_cpu_s["record"] += time.thread_time() - made
