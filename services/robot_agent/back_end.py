"""Wires the keyframe pose graph to the agent's submaps and front end.

On every keyframe switch the new keyframe joins the graph and the one just finished is
closed (loop-closure search, and a robust re-solve when a closure was accepted). Corrections
then move three things together, so the local map is never torn:
- the submaps (their voxels stay in their own frame; the new poses go to the edge);
- the front end's T_loc_odom, by the open keyframe's correction (the robot moves with it);
- the front end's registration map, rebuilt from the submaps at their corrected poses (the
  old one would hold every corrected place twice).
"""

from __future__ import annotations

import logging

import numpy as np

from services.common import voxels
from services.common.geometry import invert
from services.robot_agent.keyframe_graph import KeyframeGraph, LoopParams
from services.robot_agent.local_map import KeyframeMapper, VoxelSubmap
from services.robot_agent.localization import Localizer

log = logging.getLogger(__name__)


def submap_points(sub: VoxelSubmap, voxel_m: float) -> np.ndarray:
    """(N, 3) voxel centres of a submap, in its own frame."""
    return voxels.centres(voxels.unpack(sub.keys), voxel_m)


class BackEnd:
    """The agent's keyframe graph and what its corrections move."""

    def __init__(self, params: LoopParams, voxel_m: float, robot_id: int = 0) -> None:
        self.graph = KeyframeGraph(params)
        self.voxel_m = voxel_m
        self.robot_id = robot_id
        self.corrections = 0
        self.rebuild = True

    def on_keyframe(self, closed: VoxelSubmap | None, opened: VoxelSubmap,
                    mapper: KeyframeMapper, localizer: Localizer) -> np.ndarray:
        """Add `opened`, close `closed`; returns T_new_old of the open keyframe (identity when
        nothing moved), which the caller applies to the pose it already computed this tick."""
        self.graph.add_keyframe(opened.submap_id, opened.T_odom_submap)
        if closed is None:
            return np.eye(4)
        changed = self.graph.close(closed.submap_id, submap_points(closed, self.voxel_m))
        if not changed:
            return np.eye(4)
        T_new_old = np.eye(4)
        if opened.submap_id in changed:
            T_new_old = changed[opened.submap_id] @ invert(opened.T_odom_submap)
        mapper.set_poses(changed)
        localizer.correct(T_new_old)
        if self.rebuild:
            localizer.registrar.rebuild(
                [(submap_points(sub, self.voxel_m), sub.T_odom_submap)
                 for sub in mapper.submaps()])
        self.corrections += 1
        log.info("robot %d: loop closure moved %d keyframes (open one by %.3f m); graph %s",
                 self.robot_id, len(changed), float(np.hypot(*T_new_old[:2, 3])),
                 self.graph.stats())
        return T_new_old
