"""Every submap voxel's world key, kept sorted across plans, and each key's first observer.

The merged map keeps one observation per world voxel: the earliest by (first tick, robot),
then by the submap's place in the store (submap id within a robot) and the voxel's index in
it. When a merger correction moves a submap, its world keys change and every voxel it held
must be judged again against all the other submaps' observations of that key. Sorting all
observations again for that (a 24-robot warehouse holds 16M of them for 2M voxels at 170 s)
took 0.7 s per correction, and the merger corrects on most plans while moving about 1 % of
the observations each time. So the observations stay sorted by key here: a correction drops
the moved submaps' rows and merges their new ones in, and the first observers are read off
the sorted rows in a few linear passes.

Pure: arrays in, arrays out; no clock, no bus.
"""

from __future__ import annotations

import numpy as np


class ObservationTable:
    """Rows (world key, rank, part uid, index in part) sorted by key; rank is first tick ×
    256 + robot (robots are uint8)."""

    def __init__(self) -> None:
        self.keys = np.zeros(0, np.int64)
        self.rank = np.zeros(0, np.int64)
        self.uid = np.zeros(0, np.int32)
        self.idx = np.zeros(0, np.int32)
        self._pending: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self._dropped: set[int] = set()

    def __len__(self) -> int:
        return int(self.keys.size) + sum(p[0].size for p in self._pending)

    def add(self, keys: np.ndarray, ticks: np.ndarray, robots: np.ndarray, uids: np.ndarray,
            idx: np.ndarray) -> None:
        """Observations to hold from now on (merged in at the next `first_observers`)."""
        if keys.size:
            rank = ticks.astype(np.int64) * 256 + robots.astype(np.int64)
            self._pending.append((keys.astype(np.int64), rank, uids.astype(np.int32),
                                  idx.astype(np.int32)))

    def drop(self, uids: set[int]) -> None:
        """Forget every observation of these parts held so far (a moved submap's)."""
        if not uids:
            return
        self._dropped |= uids
        self._pending = [tuple(a[~np.isin(p[2], list(uids))] for a in p)  # type: ignore[misc]
                         for p in self._pending]

    def _flush(self) -> None:
        if self._dropped:
            gone = np.zeros(int(self.uid.max(initial=-1)) + 1, bool)
            gone[[u for u in self._dropped if u < gone.size]] = True
            keep = ~gone[self.uid]
            self.keys, self.rank, self.uid, self.idx = (
                a[keep] for a in (self.keys, self.rank, self.uid, self.idx))
            self._dropped = set()
        if not self._pending:
            return
        keys, rank, uid, idx = (np.concatenate(a) for a in zip(*self._pending, strict=True))
        self._pending = []
        order = np.argsort(keys)
        at = np.searchsorted(self.keys, keys[order])
        self.keys, self.rank, self.uid, self.idx = (
            np.insert(old, at, new[order]) for old, new in
            ((self.keys, keys), (self.rank, rank), (self.uid, uid), (self.idx, idx)))

    def first_observers(self, submap_of_uid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(sorted unique keys, row of each key's first observer): the smallest rank, then
        the smallest (submap id, index) among rows of equal rank (one robot's).
        `submap_of_uid[u]` is part u's submap id. Rows are those of `self` after the call."""
        self._flush()
        keys, rank = self.keys, self.rank
        if keys.size == 0:
            return keys, np.zeros(0, np.int64)
        first = np.ones(keys.size, bool)
        first[1:] = keys[1:] != keys[:-1]
        start = np.flatnonzero(first)
        size = np.diff(np.append(start, keys.size))
        earliest = rank == np.repeat(np.minimum.reduceat(rank, start), size)
        count = np.add.reduceat(earliest.astype(np.int32), start)
        rows = np.flatnonzero(earliest)  # each key's earliest rows, key by key
        head = np.cumsum(count) - count
        winner = rows[head]
        tied = np.flatnonzero(count > 1)
        if tied.size:
            n = count[tied]
            seg = np.cumsum(n) - n
            cand = rows[np.repeat(head[tied] - seg, n) + np.arange(int(n.sum()))]
            place = (submap_of_uid[self.uid[cand]].astype(np.int64) << 32) + self.idx[cand]
            best = place == np.repeat(np.minimum.reduceat(place, seg), n)
            winner[tied] = cand[best]  # (submap id, index) is unique within one robot
        return keys[start], winner
