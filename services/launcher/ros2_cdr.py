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
        self.u32(len(data))
        self.buf += data

    def bytes_seq(self, data: bytes) -> None:
        """A `uint8[]`/`int8[]` sequence."""
        self.u32(len(data))
        self.buf += data

    # -- common structs ----------------------------------------------------------------------
    def time(self, stamp_ns: int) -> None:
        self.i32(stamp_ns // 1_000_000_000)
        self.u32(stamp_ns % 1_000_000_000)

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


SPHERE, LINE_LIST, DELETEALL = 2, 5, 3
CLASS_RGBA = {"unexplored": (1.0, 0.55, 0.0, 0.9), "weak": (0.6, 0.2, 0.9, 0.9)}
GOAL_RGBA = (0.1, 0.8, 0.2, 1.0)


def _marker(out: Cdr, stamp_ns: int, ns: str, ident: int, kind: int, action: int,
            xyz: tuple[float, float, float], scale: float, rgba: tuple[float, ...],
            points: Sequence[tuple[float, float, float]] = ()) -> None:
    out.header(stamp_ns, MAP_FRAME)
    out.string(ns)
    out.i32(ident)
    out.i32(kind)
    out.i32(action)
    out.pose(*xyz, 0.0)
    out.f64(scale, scale, scale)
    out.f32(*rgba)
    out.time(0)  # lifetime: forever
    out.boolean(False)
    out.u32(len(points))
    for p in points:
        out.f64(*p)
    out.u32(0)  # colors
    out.string("")  # texture_resource
    out.header(0, "")  # texture: CompressedImage
    out.string("")
    out.bytes_seq(b"")
    out.u32(0)  # uv_coordinates
    out.string("")  # text
    out.string("")  # mesh_resource
    out.string("")  # mesh_file
    out.bytes_seq(b"")
    out.boolean(False)


def frontier_markers(frontiers: m.Frontiers, robot_xy: dict[int, tuple[float, float]],
                     stamp_ns: int) -> bytes:
    """visualization_msgs/MarkerArray: a DELETEALL, then a sphere per frontier region at its
    centroid (orange F_u, purple F_w; size grows with the region), a green sphere per goal
    f′ and a line from each robot to its assigned goal."""
    by_id = {f.frontier_id: f for f in frontiers.frontiers}
    lines = [((*robot_xy[r], 0.1), (*by_id[f].goal_xy, 0.1))
             for r, f in sorted(frontiers.assigned.items()) if r in robot_xy and f in by_id]
    out = Cdr()
    out.u32(1 + 2 * len(frontiers.frontiers) + (1 if lines else 0))
    _marker(out, stamp_ns, "", 0, SPHERE, DELETEALL, (0.0, 0.0, 0.0), 1.0, (0, 0, 0, 0))
    for f in frontiers.frontiers:
        size = 0.15 + 0.05 * math.log1p(f.size)
        _marker(out, stamp_ns, f"frontiers/{f.frontier_class}", f.frontier_id, SPHERE, 0,
                f.centroid, size, CLASS_RGBA[f.frontier_class])
        _marker(out, stamp_ns, "goals", f.frontier_id, SPHERE, 0, (*f.goal_xy, 0.05), 0.12,
                GOAL_RGBA)
    if lines:
        _marker(out, stamp_ns, "assignments", 0, LINE_LIST, 0, (0.0, 0.0, 0.0), 0.03,
                GOAL_RGBA, [p for pair in lines for p in pair])
    return out.bytes()
