"""spacemap's maps, poses and frontiers as ROS 2 messages in CDR (little endian), pure.

Written here rather than through mcap-ros2-support's encoder, which writes `uint8[]`/`int8[]`
one element at a time in Python (seconds for one merged cloud): here the arrays go in as one
numpy buffer. `tests/test_recorders.py` decodes every message back with mcap-ros2-support's
decoder, so the two agree on the wire format.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence

import numpy as np

from schemas import messages as m

MAP_FRAME = "map"


def base_frame(robot: int) -> str:
    return f"robot_{robot}/base_link"


class Cdr:
    """A CDR buffer: the 4-byte encapsulation header, then fields aligned to their size
    (counted from the end of the header)."""

    def __init__(self) -> None:
        self.buf = bytearray(b"\x00\x01\x00\x00")  # CDR_LE

    def _align(self, size: int) -> None:
        self.buf += b"\x00" * ((-(len(self.buf) - 4)) % size)

    def _put(self, fmt: str, size: int, *values: object) -> None:
        self._align(size)
        self.buf += struct.pack("<" + fmt, *values)

    def u8(self, v: int) -> None:
        self.buf.append(v & 0xFF)

    def boolean(self, v: bool) -> None:
        self.buf.append(1 if v else 0)

    def i32(self, v: int) -> None:
        self._put("i", 4, v)

    def u32(self, v: int) -> None:
        self._put("I", 4, v)

    def f32(self, *v: float) -> None:
        self._put(f"{len(v)}f", 4, *v)

    def f64(self, *v: float) -> None:
        self._put(f"{len(v)}d", 8, *v)

    def string(self, s: str) -> None:
        data = s.encode() + b"\x00"
        self._put("I", 4, len(data))
        self.buf += data

    def bytes_seq(self, data: bytes) -> None:
        """A `uint8[]`/`int8[]` sequence."""
        self.u32(len(data))
        self.buf += data

    # -- common structs ----------------------------------------------------------------------
    def time(self, stamp_ns: int) -> None:
        self._put("iI", 4, stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000)

    def header(self, stamp_ns: int, frame_id: str) -> None:
        self.time(stamp_ns)
        self.string(frame_id)

    def pose(self, x: float, y: float, z: float, yaw: float) -> None:
        self.f64(x, y, z)
        self.f64(*yaw_quaternion(yaw))

    def bytes(self) -> bytes:
        return bytes(self.buf)


def yaw_quaternion(yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by `yaw` about +z."""
    return 0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0)


_FLOAT32, _UINT32 = 7, 6


def point_cloud2(points: np.ndarray, colors: np.ndarray | None, stamp_ns: int,
                 frame_id: str = MAP_FRAME) -> bytes:
    """sensor_msgs/PointCloud2: x, y, z float32 and, with `colors`, `rgb` packed as RViz
    reads it (0x00RRGGBB in a 4-byte field); one row, dense."""
    pts = np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3)
    fields: list[tuple[str, int, int]] = [("x", 0, _FLOAT32), ("y", 4, _FLOAT32),
                                          ("z", 8, _FLOAT32)]
    if colors is not None:
        c = np.asarray(colors, dtype=np.uint32).reshape(-1, 3)
        rgb = (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]
        rec = np.empty(len(pts), dtype=[("xyz", "<f4", 3), ("rgb", "<u4")])
        rec["xyz"], rec["rgb"] = pts, rgb
        fields.append(("rgb", 12, _UINT32))
        data, step = rec.tobytes(), 16
    else:
        data, step = pts.astype("<f4").tobytes(), 12
    out = Cdr()
    out.header(stamp_ns, frame_id)
    out.u32(1)
    out.u32(len(pts))
    out.u32(len(fields))
    for name, offset, datatype in fields:
        out.string(name)
        out.u32(offset)
        out.u8(datatype)
        out.u32(1)
    out.boolean(False)
    out.u32(step)
    out.u32(step * len(pts))
    out.bytes_seq(data)
    out.boolean(True)
    return out.bytes()


def occupancy_grid(grid: m.OccupancyGrid, stamp_ns: int, frame_id: str = MAP_FRAME) -> bytes:
    """nav_msgs/OccupancyGrid: our cells are already ROS's (-1 unknown, 0 free, 100
    occupied; row = y, origin at cell (0, 0)'s outer corner)."""
    h, w = grid.cells.shape
    out = Cdr()
    out.header(stamp_ns, frame_id)
    out.time(stamp_ns)  # map_load_time
    out.f32(grid.resolution_m)
    out.u32(w)
    out.u32(h)
    out.pose(grid.origin_x, grid.origin_y, 0.0, 0.0)
    out.bytes_seq(np.ascontiguousarray(grid.cells, dtype=np.int8).tobytes())
    return out.bytes()


def odometry(robot: int, pose: m.Pose2D, stamp_ns: int, child: str | None = None) -> bytes:
    """nav_msgs/Odometry of a planar pose in the map frame (covariance and twist unknown: 0)."""
    out = Cdr()
    out.header(stamp_ns, MAP_FRAME)
    out.string(child or base_frame(robot))
    # pose, its covariance, the twist and its covariance: 85 float64 in a row
    out.f64(pose.x, pose.y, 0.0, *yaw_quaternion(pose.yaw), *_ODOM_ZEROS)
    return out.bytes()


_ODOM_ZEROS = (0.0,) * (36 + 6 + 36)


def tf_message(transforms: Sequence[tuple[str, m.Pose2D]], stamp_ns: int) -> bytes:
    """tf2_msgs/TFMessage: map → each named child frame at a planar pose."""
    out = Cdr()
    out.u32(len(transforms))
    for child, pose in transforms:
        out.header(stamp_ns, MAP_FRAME)
        out.string(child)
        out.f64(pose.x, pose.y, 0.0, *yaw_quaternion(pose.yaw))
    return out.bytes()


SPHERE_LIST, LINE_LIST, DELETEALL = 7, 5, 3
CLASS_RGBA = {"unexplored": (1.0, 0.55, 0.0, 0.9), "weak": (0.6, 0.2, 0.9, 0.9)}
GOAL_RGBA = (0.1, 0.8, 0.2, 1.0)


def _marker_tail() -> bytes:
    """What every marker here ends with, from `texture_resource` on (all empty): only
    4-byte alignment inside, so the same bytes wherever a 4-aligned tail starts."""
    out = Cdr()
    out.string("")  # texture_resource
    out.header(0, "")  # texture: CompressedImage
    out.string("")
    out.bytes_seq(b"")
    out.u32(0)  # uv_coordinates
    out.string("")  # text
    out.string("")  # mesh_resource
    out.string("")  # mesh_file
    out.bytes_seq(b"")
    out.boolean(False)  # mesh_use_embedded_materials
    return out.bytes()[4:]


_TAIL = _marker_tail()


def _marker(out: Cdr, stamp_ns: int, ns: str, kind: int, action: int, scale: float,
            rgba: tuple[float, ...], points: Sequence[tuple[float, float, float]] = ()) -> None:
    out.header(stamp_ns, MAP_FRAME)
    out.string(ns)
    out._put("3i", 4, 0, kind, action)  # id, type, action
    out.f64(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, scale, scale, scale)  # identity pose, scale
    out.f32(*rgba)
    out.time(0)  # lifetime: forever
    out.boolean(False)  # frame_locked
    out.u32(len(points))
    if points:
        out.f64(*(v for p in points for v in p))
    out.u32(0)  # colors: one for all
    out._align(4)
    out.buf += _TAIL


def frontier_markers(frontiers: m.Frontiers, robot_xy: dict[int, tuple[float, float]],
                     stamp_ns: int) -> bytes:
    """visualization_msgs/MarkerArray: a DELETEALL, then a sphere list per frontier class
    at the regions' centroids (orange F_u, purple F_w), one of the goals f′ (green) and a
    line list from each robot to its assigned goal."""
    by_id = {f.frontier_id: f for f in frontiers.frontiers}
    lines = [p for r, f in sorted(frontiers.assigned.items()) if r in robot_xy and f in by_id
             for p in ((*robot_xy[r], 0.1), (*by_id[f].goal_xy, 0.1))]
    groups = [(f"frontiers/{cls}", SPHERE_LIST, 0.25, CLASS_RGBA[cls],
               [f.centroid for f in frontiers.frontiers if f.frontier_class == cls])
              for cls in ("unexplored", "weak")]
    groups.append(("goals", SPHERE_LIST, 0.12, GOAL_RGBA,
                   [(*f.goal_xy, 0.05) for f in frontiers.frontiers]))
    groups.append(("assignments", LINE_LIST, 0.03, GOAL_RGBA, lines))
    out = Cdr()
    out.u32(1 + len(groups))
    _marker(out, stamp_ns, "", SPHERE_LIST, DELETEALL, 1.0, (0.0, 0.0, 0.0, 0.0))
    for ns, kind, scale, rgba, points in groups:
        _marker(out, stamp_ns, ns, kind, 0, scale, rgba, points)
    return out.bytes()
