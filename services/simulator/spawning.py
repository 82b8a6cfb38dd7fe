"""Automatic spawn poses for a world file that names none: a formation that fits in free space.

The robots form the usual rows of three 0.6 m apart facing +x (`worlds.SpawnGrid`). The
formation is placed on the 2D obstacle grid of the evaluator (`free_space.obstacle_grid`, the
same footprints the 2D truth uses) where every robot's centre has at least `clearance_m` of
free floor around it, all robots lie in one connected free region, and that region is inside
the building (it does not touch the grid border) when such a region exists. Among the places
that fit, the one with the most room wins, ties going to the lowest (row, col): deterministic,
so the simulator and the evaluator always agree on the spawns of a world.
"""

from __future__ import annotations

import logging

import mujoco
import numpy as np
from scipy import ndimage

from services.evaluator.free_space import obstacle_grid
from services.simulator.worlds import Pose, SpawnGrid

log = logging.getLogger(__name__)

RESOLUTION_M = 0.05
BAND_Z_M = (0.03, 0.40)  # the robot's height band, as the evaluator's 2D truth
CLEARANCE_M = 0.35  # half diagonal of the Waffle footprint (0.21 m) plus a margin


def _inner_regions(free: np.ndarray) -> tuple[np.ndarray, int]:
    """4-connected labels of `free`; regions touching the grid border are dropped if any other
    region exists (they are the outside of a closed building)."""
    labels, count = ndimage.label(free)
    border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    inner = np.setdiff1d(np.arange(1, count + 1), border)
    if len(inner):
        labels = np.where(np.isin(labels, inner), labels, 0)
    return labels, count


def _shifted(a: np.ndarray, dr: int, dc: int, fill: float) -> np.ndarray:
    """out[r, c] = a[r + dr, c + dc], `fill` outside the grid."""
    out = np.full_like(a, fill)
    h, w = a.shape
    rs, cs = slice(max(0, -dr), min(h, h - dr)), slice(max(0, -dc), min(w, w - dc))
    rd, cd = slice(max(0, dr), min(h, h + dr)), slice(max(0, dc), min(w, w + dc))
    out[rs, cs] = a[rd, cd]
    return out


def auto_spawns(model: mujoco.MjModel, n: int, clearance_m: float = CLEARANCE_M) -> list[Pose]:
    """Poses of `n` robots close together in the free space of `model` (the world alone)."""
    spec, occupied = obstacle_grid(model, BAND_Z_M, RESOLUTION_M)
    room_m = ndimage.distance_transform_edt(~occupied) * RESOLUTION_M
    labels, _ = _inner_regions(room_m >= clearance_m)
    offsets = SpawnGrid(x0=0.0, y_centre=0.0).poses(n)
    # For a formation anchored at cell (r, c): its smallest room and whether one region holds it.
    anchor_room = np.full(room_m.shape, np.inf)
    first = None
    same_region = np.ones(room_m.shape, bool)
    for ox, oy, _ in offsets:
        dr, dc = round(oy / RESOLUTION_M), round(ox / RESOLUTION_M)
        lab = _shifted(labels, dr, dc, 0)
        first = lab if first is None else first
        same_region &= (lab > 0) & (lab == first)
        anchor_room = np.minimum(anchor_room, _shifted(room_m, dr, dc, 0.0))
    score = np.where(same_region, anchor_room, -1.0)
    r, c = np.unravel_index(int(np.argmax(score)), score.shape)  # first maximum: deterministic
    if score[r, c] < clearance_m:
        raise ValueError(f"no free place for {n} robots {clearance_m} m from every obstacle")
    x0, y0 = spec.centre_of(np.array([[r, c]]))[0]
    poses = [(float(round(x0 + ox, 3)), float(round(y0 + oy, 3)), yaw) for ox, oy, yaw in offsets]
    log.info("automatic spawns for %d robots around (%.2f, %.2f), %.2f m of room",
             n, x0, y0, score[r, c])
    return poses
