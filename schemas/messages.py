"""Every message on the bus (SPEC §2), as frozen pydantic models.

Conventions: poses named `T_to_from` are 4×4 float64 homogeneous transforms; planar poses are
`Pose2D` (metres, radians, yaw about +z); times are `stamp_ns` (sim time, integer ns) and
`tick` (the lockstep tick the data belongs to). Frames: `world` = global frame of the mission,
`base` = robot base on the floor, `cam` = optical camera frame (x right, y down, z forward),
`submap` = the keyframe a submap's points are expressed in.
"""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from schemas.arrays import ArraySpec

SCHEMA_VERSION = 1

RobotId = Annotated[int, Field(ge=0, le=255)]
# Bounded so an absurd value is refused at decode, not carried into id arithmetic (submap ids
# are tick × a per-epoch stride): 2^31 ticks is 6.8 years at 0.1 s; stamps fit an int64.
MAX_TICK = 2**31 - 1
Tick = Annotated[int, Field(ge=0, le=MAX_TICK)]
StampNs = Annotated[int, Field(ge=0, le=2**63 - 1)]


class Model(BaseModel):
    model_config = ConfigDict(
        frozen=True, extra="forbid", allow_inf_nan=False, arbitrary_types_allowed=True
    )


class Message(Model):
    """Base of every bus message: `kind` names the model, `v` its schema version."""

    KIND: ClassVar[str] = ""
    v: Literal[1] = SCHEMA_VERSION


class Pose2D(Model):
    """Planar pose: position (m) and yaw (rad, about +z) of `base` in the named frame."""

    x: float
    y: float
    yaw: float


class Clock(Message):
    """Sim clock; published once per tick before that tick's sensor data."""

    KIND: ClassVar[str] = "clock"
    kind: Literal["clock"] = "clock"
    tick: Tick
    stamp_ns: StampNs
    dt_ns: Annotated[int, Field(gt=0)]
    lockstep: bool
    camera_tick: bool = Field(description="True when this tick carries RGB-D frames")


class RgbdFrame(Message):
    """One RGB-D frame of robot `robot_id`'s camera."""

    KIND: ClassVar[str] = "rgbd"
    kind: Literal["rgbd"] = "rgbd"
    robot_id: RobotId
    tick: Tick
    stamp_ns: StampNs
    depth_m: Annotated[np.ndarray, ArraySpec("float32", (None, None), compress=True)] = Field(
        description="(H, W) float32 z-depth along the optical axis in metres; 0 = no return"
    )
    rgb: Annotated[np.ndarray, ArraySpec("uint8", (None, None, 3), compress=True)] = Field(
        description="(H, W, 3) uint8 colour image, row 0 at the top"
    )
    K: Annotated[np.ndarray, ArraySpec("float64", (3, 3))] = Field(
        description="(3, 3) pinhole intrinsics of the optical frame, pixels"
    )
    T_base_cam: Annotated[np.ndarray, ArraySpec("float64", (4, 4))] = Field(
        description="(4, 4) extrinsics: optical camera frame → robot base frame"
    )
    range_max_m: Annotated[float, Field(gt=0)]


class Odometry(Message):
    """Wheel odometry (drifting) of robot `robot_id`.

    The odometry frame is the world frame at spawn: robots start from known initial poses
    (the paper's problem setting), so `pose_odom` equals the true pose at tick 0 and then drifts.
    """

    KIND: ClassVar[str] = "odom"
    kind: Literal["odom"] = "odom"
    robot_id: RobotId
    tick: Tick
    stamp_ns: StampNs
    pose_odom: Pose2D
    v_mps: float
    omega_radps: float


class CmdVel(Message):
    """Velocity command; `tick` is the tick it answers (lockstep handshake)."""

    KIND: ClassVar[str] = "cmd_vel"
    kind: Literal["cmd_vel"] = "cmd_vel"
    robot_id: RobotId
    tick: Tick
    v_mps: float
    omega_radps: float


class RobotPose(Message):
    """An agent's estimate of its own pose in the world frame."""

    KIND: ClassVar[str] = "pose"
    kind: Literal["pose"] = "pose"
    robot_id: RobotId
    tick: Tick
    stamp_ns: StampNs
    pose_world: Pose2D
    state: str = Field(default="", max_length=32, description="navigation state, for display")
    wall_direction_rad: float | None = Field(
        default=None, ge=-np.pi / 4, le=np.pi / 4, allow_inf_nan=False,
        description="the walls' direction this agent learned from its first frames, world "
        "frame, modulo 90° in [−π/4, π/4]; None until it has learned one (teammates take the "
        "consensus: services/robot_agent/wall_heading.py)")
    odometry_stats: list[Annotated[float, Field(allow_inf_nan=False)]] | None = Field(
        default=None, min_length=7, max_length=7,
        description="this agent's own odometry-calibration normal equations (scale numerator "
        "and denominator, turn normal matrix xx, xy, yy, right-hand side; "
        "services/robot_agent/odometry_calibration.py), for teammates that pool them; None "
        "when not shared")


class Submap(Message):
    """A keyframe submap, or a delta of it: the voxels added since the last message.

    Points are in the `submap` frame, quantized to int16 millimetres, stored column-wise.
    """

    KIND: ClassVar[str] = "submap"
    kind: Literal["submap"] = "submap"
    robot_id: RobotId
    epoch: Annotated[int, Field(ge=0)] = Field(
        default=0, description="tick at which this agent process started; new after a restart"
    )
    submap_id: Annotated[int, Field(ge=0)] = Field(
        description="unique per robot across agent restarts"
    )
    seq: Annotated[int, Field(ge=0)] = Field(
        description="per (robot, epoch) message counter, no gaps"
    )
    tick: Tick
    stamp_ns: StampNs
    T_world_submap: Annotated[np.ndarray, ArraySpec("float64", (4, 4))] = Field(
        description="(4, 4) the agent's estimate of the submap frame in the world frame"
    )
    T_odom_submap: Annotated[np.ndarray, ArraySpec("float64", (4, 4))] | None = Field(
        default=None, description="(4, 4) the submap frame in the agent's own odometry frame, "
        "which corrections never move: two submaps' relative pose is exact whatever "
        "correction arrived between their reports (None: the edge uses T_world_submap)")
    points_mm: Annotated[np.ndarray, ArraySpec("int16", (3, None), compress=True,
                                               filter="delta", level=6)] = Field(
        description="(3, N) int16 voxel-centre coordinates in the submap frame, millimetres"
    )
    offsets: Annotated[np.ndarray, ArraySpec("uint8", (None,), compress=True, level=6)] = Field(
        default_factory=lambda: np.zeros(0, np.uint8),
        description="(N,) uint8 where in its voxel each voxel's mean point lies: cell (i, j, k) "
        "of an L×L×L split of the voxel along x, y, z, coded (i·L + j)·L + k with L = "
        "`offset_levels`; empty: no means (the centres stand for the points)")
    offset_levels: Annotated[int, Field(ge=1, le=6)] = Field(
        default=1, description="L, cells per voxel edge of `offsets`")
    colors: Annotated[np.ndarray, ArraySpec("uint8", (None, 3), compress=True,
                                            filter="delta", level=6)] = Field(
        description="(N, 3) uint8 RGB per point"
    )
    counts: Annotated[np.ndarray, ArraySpec("uint16", (None,), compress=True,
                                            filter="shuffle", level=6)] = Field(
        description="(N,) observations per voxel so far"
    )
    free_cells: Annotated[np.ndarray, ArraySpec("int16", (2, None), compress=True,
                                                filter="delta", level=6)] = Field(
        description="(2, M) int16 floor cells seen free, in submap-frame grid cells (x, y)"
    )
    cell_m: Annotated[float, Field(gt=0)] = Field(description="size of a free cell, metres")

    @model_validator(mode="after")
    def _per_voxel_arrays_agree(self) -> Submap:
        n = self.points_mm.shape[1]
        if self.colors.shape[0] != n or self.counts.shape[0] != n:
            raise ValueError(f"{n} points but {self.colors.shape[0]} colours and "
                             f"{self.counts.shape[0]} counts")
        if self.offsets.shape[0] not in (0, n):
            raise ValueError(f"{n} points but {self.offsets.shape[0]} offsets")
        if self.offsets.size and int(self.offsets.max()) >= self.offset_levels**3:
            raise ValueError(f"offset code {int(self.offsets.max())} ≥ {self.offset_levels}³")
        return self


class Correction(Message):
    """Corrected submap poses from the edge's pose graph."""

    KIND: ClassVar[str] = "correction"
    kind: Literal["correction"] = "correction"
    robot_id: RobotId
    tick: Tick
    submap_ids: Annotated[np.ndarray, ArraySpec("int32", (None,))]
    T_world_submap: Annotated[np.ndarray, ArraySpec("float64", (None, 4, 4))] = Field(
        description="(N, 4, 4) corrected poses, one per submap id"
    )


FrontierClass = Literal["unexplored", "weak"]


class Goal(Message):
    """An assigned exploration goal: the translated frontier f′ on the merged grid."""

    KIND: ClassVar[str] = "goal"
    kind: Literal["goal"] = "goal"
    robot_id: RobotId
    tick: Tick
    goal_id: Annotated[int, Field(ge=0)]
    x: float
    y: float
    frontier_class: FrontierClass
    revenue: float
    cancel: bool = Field(default=False, description="True withdraws goal `goal_id`: stop it")
    look_xy: tuple[float, float] | None = Field(
        default=None, description="world (x, y), m, the robot faces on arrival before it reports "
        "reached (the frontier region's centroid); None: report on arrival")
    queued: bool = Field(
        default=False, description="a successor: the robot keeps it and adopts it as soon as "
        "its current goal ends (reached, invalid, unreachable), instead of idling until the "
        "next plan; a later queued goal, or any new goal, replaces it; with `cancel`, "
        "withdraws it")


GoalState = Literal["active", "reached", "invalid", "unreachable"]


class GoalStatus(Message):
    """The agent's report on its current goal."""

    KIND: ClassVar[str] = "goal_status"
    kind: Literal["goal_status"] = "goal_status"
    robot_id: RobotId
    tick: Tick
    goal_id: Annotated[int, Field(ge=0)]
    status: GoalState
    reason: str = Field(default="", max_length=200)


class OccupancyGrid(Message):
    """The merged 2D grid: -1 unknown, 0 free, 100 occupied (ROS convention)."""

    KIND: ClassVar[str] = "grid"
    kind: Literal["grid"] = "grid"
    tick: Tick
    resolution_m: Annotated[float, Field(gt=0)]
    origin_x: float = Field(description="world x of cell (row 0, col 0)'s outer corner, m")
    origin_y: float
    cells: Annotated[np.ndarray, ArraySpec("int8", (None, None), compress=True)] = Field(
        description="(H, W) int8, row = y index, col = x index"
    )


class Frontier(Model):
    """One frontier region and its translated goal f′."""

    frontier_id: Annotated[int, Field(ge=0)]
    frontier_class: FrontierClass
    centroid: tuple[float, float, float]
    goal_xy: tuple[float, float]
    size: Annotated[int, Field(ge=1)]
    gain: float
    importance: float


class Frontiers(Message):
    """Current frontier regions; `complete` is the edge's exploration-complete verdict."""

    KIND: ClassVar[str] = "frontiers"
    kind: Literal["frontiers"] = "frontiers"
    tick: Tick
    frontiers: list[Frontier]
    complete: bool
    assigned: dict[int, int] = Field(default_factory=dict, description="robot id → frontier id")


class EdgeAck(Message):
    """The edge's answer to a planning tick (lockstep handshake); spacemap's addition to §2."""

    KIND: ClassVar[str] = "edge_ack"
    kind: Literal["edge_ack"] = "edge_ack"
    tick: Tick


class CloudRequest(Message):
    """Query body of `map/cloud`; an empty query payload means the merged map."""

    KIND: ClassVar[str] = "cloud_request"
    kind: Literal["cloud_request"] = "cloud_request"
    robot_id: int = Field(default=-1, ge=-1, le=255, description="-1 = merged P*, else robot's")
    since_version: int | None = Field(
        default=None, ge=-1,
        description="None: the whole map, no keys. -1: the whole map with its voxel keys and "
        "version. v >= 0: only the voxels added or moved since the edge's version v (the "
        "whole map where it was rebuilt since)")


class GridRequest(Message):
    """Query body of `map/robot_grid`: one robot's own 2D grid (for the evaluator's overlap)."""

    KIND: ClassVar[str] = "grid_request"
    kind: Literal["grid_request"] = "grid_request"
    robot_id: RobotId


class Cloud(Message):
    """The merged cloud P* (or one robot's part of it), in the world frame."""

    KIND: ClassVar[str] = "cloud"
    kind: Literal["cloud"] = "cloud"
    tick: Tick
    robot_id: int = Field(default=-1, description="-1 for the merged map")
    points_world: Annotated[np.ndarray, ArraySpec("float32", (None, 3), compress=True)] = Field(
        description="(N, 3) float32 voxel points in the world frame, metres"
    )
    colors: Annotated[np.ndarray, ArraySpec("uint8", (None, 3), compress=True)]
    robot_ids: Annotated[np.ndarray, ArraySpec("uint8", (None,), compress=True)] = Field(
        description="(N,) robot id of each point's first observer"
    )
    voxel_keys: Annotated[np.ndarray, ArraySpec("int64", (None,), compress=True)] = Field(
        default_factory=lambda: np.zeros(0, np.int64),
        description="(N,) int64 packed world voxel key of each point, sorted (one point per "
        "key), when the request gave since_version; else empty")
    version: int = Field(default=0, ge=0, description="the edge's map version of this answer")
    delta: bool = Field(default=False, description="only the voxels added or moved since the "
                        "request's since_version: replace those keys, keep the rest")

    @model_validator(mode="after")
    def _keys_match_points(self) -> Cloud:
        n = len(self.points_world)
        if len(self.colors) != n or len(self.robot_ids) != n:
            raise ValueError(f"colors and robot_ids must have the {n} rows of points_world")
        if self.voxel_keys.size not in (0, n):
            raise ValueError(f"voxel_keys holds {self.voxel_keys.size} keys for {n} points")
        if self.voxel_keys.size > 1 and not np.all(np.diff(self.voxel_keys) > 0):
            raise ValueError("voxel_keys must be sorted and unique")
        if self.delta and self.voxel_keys.size != n:
            raise ValueError("a delta cloud needs voxel_keys")
        return self


class SubmapInfo(Model):
    """One submap in an inventory."""

    epoch: Annotated[int, Field(ge=0)]
    submap_id: Annotated[int, Field(ge=0)]
    voxels: Annotated[int, Field(ge=0)] = Field(description="distinct voxels held")


class Inventory(Message):
    """What a process holds of the robots' submaps: an agent's own (what it produced and
    published) on `robot/{id}/inventory`, or the edge's (what it merged) on `map/inventory`.
    Lets anyone check that nothing a robot mapped was lost on the way."""

    KIND: ClassVar[str] = "inventory"
    kind: Literal["inventory"] = "inventory"
    tick: Tick
    submaps: dict[int, list[SubmapInfo]] = Field(description="robot id → its submaps")


class GtPose(Message):
    """Ground-truth pose, for the evaluator only."""

    KIND: ClassVar[str] = "gt_pose"
    kind: Literal["gt_pose"] = "gt_pose"
    robot_id: RobotId
    tick: Tick
    stamp_ns: StampNs
    pose_world: Pose2D


MESSAGE_TYPES: dict[str, type[Message]] = {
    cls.KIND: cls
    for cls in (
        Clock, RgbdFrame, Odometry, CmdVel, RobotPose, Submap, Correction, Goal, GoalStatus,
        OccupancyGrid, Frontiers, EdgeAck, CloudRequest, GridRequest, Cloud, Inventory, GtPose,
    )
}
