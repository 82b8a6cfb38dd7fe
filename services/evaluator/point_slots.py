"""A live map's points, one slot each: new points are appended, gone ones marked dead in
place, and the slots compacted once half are dead. Why: the tallies kept their per-point
arrays sorted by id, and inserting each sample's points into six of them cost more than
scoring those points (docs/benchmarks.md, issue 13); the id order now lives in a separate
index of ids and slots (`incremental.MapTally`)."""

from __future__ import annotations

import numpy as np

MIN_CAPACITY = 1024


class PointSlots:
    """Per slot: the point's id, coordinates, own ghost test, whether it counts, its voxel's
    key and its truth cell. `counting` is False in dead slots."""

    def __init__(self) -> None:
        self.size = 0  # slots in use, live or dead
        self.dead = 0
        self.ids = np.zeros(0, np.uint64)
        self.points = np.zeros((0, 3))  # world frame, metres
        self.near = np.zeros(0, bool)
        self.counting = np.zeros(0, bool)
        self.alive = np.zeros(0, bool)
        self.voxel = np.zeros(0, np.int64)
        self.cell = np.zeros(0, np.int64)

    FIELDS = ("ids", "points", "near", "counting", "alive", "voxel", "cell")

    def append(self, ids: np.ndarray, points: np.ndarray, near: np.ndarray,
               counting: np.ndarray, voxel: np.ndarray, cell: np.ndarray) -> np.ndarray:
        """Store new points; their slots."""
        n, end = len(ids), self.size + len(ids)
        if end > self.ids.size:
            capacity = max(MIN_CAPACITY, 2 * end)
            for name in self.FIELDS:
                old = getattr(self, name)
                grown = np.zeros((capacity, *old.shape[1:]), old.dtype)
                grown[:self.size] = old[:self.size]
                setattr(self, name, grown)
        at = slice(self.size, end)
        self.ids[at], self.points[at], self.near[at] = ids, points, near
        self.counting[at], self.alive[at] = counting, True
        self.voxel[at], self.cell[at] = voxel, cell
        self.size = end
        return np.arange(end - n, end)

    def kill(self, slots: np.ndarray) -> None:
        self.alive[slots] = False
        self.counting[slots] = False
        self.dead += len(slots)

    def compact(self) -> np.ndarray | None:
        """Move the live slots to the front once half are dead; the new slot of each old one
        (-1 for the dead), or None when nothing moved."""
        if self.dead < max(MIN_CAPACITY, self.size // 2):
            return None
        live = np.flatnonzero(self.alive[:self.size])
        for name in self.FIELDS:
            setattr(self, name, getattr(self, name)[live])
        moved = np.full(self.size, -1, np.int64)
        moved[live] = np.arange(live.size)
        self.size, self.dead = live.size, 0
        return moved

    def used(self, name: str) -> np.ndarray:
        """One field over the slots in use (a view)."""
        return getattr(self, name)[:self.size]
