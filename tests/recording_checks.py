"""Reading mission.mcap and mission.rrd back with the reference decoders (mcap-ros2-support's
ROS 2 decoder, rerun's RrdReader), for the recorder tests."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rerun.chunk import RrdReader


def mcap_messages(path: Path) -> dict[str, list[tuple[str, Any]]]:
    """topic → [(schema name, decoded ROS 2 message)] in log-time order."""
    out: dict[str, list[tuple[str, Any]]] = defaultdict(list)
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, _, ros in reader.iter_decoded_messages(log_time_order=True):
            out[channel.topic].append((schema.name, ros))
    return dict(out)


def cloud_points(msg: Any) -> np.ndarray:
    """(N, 3) float64 x, y, z of a sensor_msgs/PointCloud2 with float32 x, y, z fields."""
    offsets = {f.name: f.offset for f in msg.fields}
    raw = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(-1, msg.point_step)
    cols = [raw[:, offsets[a]:offsets[a] + 4].copy().view("<f4")[:, 0] for a in "xyz"]
    return np.stack(cols, axis=1).astype(np.float64)


def grid_cells(msg: Any) -> np.ndarray:
    """(H, W) int8 cells of a nav_msgs/OccupancyGrid (row = y)."""
    return np.asarray(msg.data, dtype=np.int8).reshape(msg.info.height, msg.info.width)


def pose_xyyaw(msg: Any) -> tuple[int, float, float, float]:
    """(stamp ns, x, y, yaw) of a nav_msgs/Odometry."""
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
    return stamp, p.x, p.y, 2.0 * np.arctan2(q.z, q.w)


def rrd_entities(path: Path) -> tuple[dict[str, int], tuple[float, float] | None]:
    """(entity path → rows, (first, last) sim_time in s over every entity) of an .rrd."""
    rows: dict[str, int] = defaultdict(int)
    lo, hi = np.inf, -np.inf
    for chunk in RrdReader(path).stream().to_chunks():
        rows[chunk.entity_path] += chunk.num_rows
        if "sim_time" in chunk.timeline_names:
            ns = np.asarray(chunk.to_record_batch().column("sim_time").cast("int64"))
            if len(ns):
                lo, hi = min(lo, ns.min() * 1e-9), max(hi, ns.max() * 1e-9)
    return dict(rows), ((lo, hi) if np.isfinite(lo) else None)



def rrd_blueprint_views(path: Path) -> tuple[str, set[tuple[str, str, str]]] | None:
    """(application id, {(view class, name, origin)}) of the .rrd's first blueprint store,
    or None when the file holds no blueprint."""
    reader = RrdReader(path)
    stores = reader.blueprints()
    if not stores:
        return None
    views: set[tuple[str, str, str]] = set()
    for chunk in reader.stream(store=stores[0]).to_chunks():
        batch = chunk.to_record_batch()
        if "ViewBlueprint:class_identifier" not in batch.schema.names:
            continue
        for row in batch.to_pylist():
            views.add((row["ViewBlueprint:class_identifier"][0],
                       row["ViewBlueprint:display_name"][0],
                       row["ViewBlueprint:space_origin"][0]))
    return stores[0].application_id, views
