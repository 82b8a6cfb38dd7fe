"""Every submap voxel's world key, kept sorted across plans, and each key's first observer.

The merged map keeps one observation per world voxel: the earliest by (first tick, robot),
then by the submap's place in the store (submap id within a robot) and the voxel's index in
it. When a merger correction moves a submap, its world keys change and every voxel it held
must be judged again against all the other submaps' observations of that key. Sorting all
observations again for that (a 24-robot warehouse holds 16M of them for 2M voxels at 170 s)
took 0.7 s per correction, and the merger corrects on most plans while moving about 1 % of
the observations each time. So the observations stay sorted by key here, and only the keys
whose observations changed are judged again: a moved submap's rows are found by the keys it
held and marked dropped in place (their rank set to `DROPPED`, so they never come first;
they are swept out once they are a quarter of the rows), its new rows are merged in, and
the first observers of the keys either touched are read off their rows. Judging every key
on every correction, and copying the 16M rows to drop the moved ones, took 1.8 s per plan
late in a 24-robot warehouse mission (bench/bench_edge_replay.py --profile).

Pure: arrays in, arrays out; no clock, no bus.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.common.arrays import unique_sorted

DROPPED = np.iinfo(np.int64).max  # the rank of a row whose submap moved


@dataclass(frozen=True)
class FirstObservers:
    """The keys whose observations changed since the last `first_observers`, sorted and
    unique; per key whether any observation is left (`held`) and, where held, its first
    observer's rank (first tick × 256 + robot), part uid and index in that part."""

    keys: np.ndarray  # (K,) int64
    held: np.ndarray  # (K,) bool
    rank: np.ndarray  # (K,) int64
    uid: np.ndarray  # (K,) int32
    idx: np.ndarray  # (K,) int32


def _ranges(lo: np.ndarray, n: np.ndarray) -> np.ndarray:
    """The rows lo[i] .. lo[i] + n[i] − 1 of every i, concatenated in order."""
    total = int(n.sum())
    head = np.cumsum(n) - n
    return np.repeat(lo - head, n) + np.arange(total)


class ObservationTable:
    """Rows (world key, rank, part uid, index in part) sorted by key; rank is first tick ×
    256 + robot (robots are uint8), or `DROPPED`."""

    def __init__(self) -> None:
        self.keys = np.zeros(0, np.int64)
        self.rank = np.zeros(0, np.int64)
        self.uid = np.zeros(0, np.int32)
        self.idx = np.zeros(0, np.int32)
        self._pending: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self._touched: list[np.ndarray] = []  # keys that lost rows since the last judgement
        self._dropped_rows = 0

    def __len__(self) -> int:
        """Observations held (dropped rows not counted)."""
        return int(self.keys.size) - self._dropped_rows + sum(p[0].size for p in self._pending)

    def add(self, keys: np.ndarray, ticks: np.ndarray, robots: np.ndarray, uids: np.ndarray,
            idx: np.ndarray) -> None:
        """Observations to hold from now on (merged in at the next `first_observers`)."""
        if keys.size:
            rank = ticks.astype(np.int64) * 256 + robots.astype(np.int64)
            self._pending.append((keys.astype(np.int64), rank, uids.astype(np.int32),
                                  idx.astype(np.int32)))

    def drop(self, parts: dict[int, np.ndarray]) -> None:
        """Forget every observation of these parts held so far; `parts[uid]` holds every
        world key the part was added with (its rows are looked up by them)."""
        if not parts:
            return
        gone = np.array(sorted(parts), np.int32)
        self._pending = [tuple(a[~np.isin(p[2], gone)] for a in p)  # type: ignore[misc]
                         for p in self._pending]
        for uid, keys in parts.items():
            touched = unique_sorted(keys)
            lo = np.searchsorted(self.keys, touched, "left")
            rows = _ranges(lo, np.searchsorted(self.keys, touched, "right") - lo)
            rows = rows[(self.uid[rows] == uid) & (self.rank[rows] != DROPPED)]
            self.rank[rows] = DROPPED
            self._dropped_rows += rows.size
            self._touched.append(touched)

    def _merge_pending(self) -> np.ndarray:
        """Insert the pending rows; their keys, sorted."""
        if not self._pending:
            return np.zeros(0, np.int64)
        keys, rank, uid, idx = (np.concatenate(a) for a in zip(*self._pending, strict=True))
        self._pending = []
        order = np.argsort(keys)
        at = np.searchsorted(self.keys, keys[order])
        self.keys, self.rank, self.uid, self.idx = (
            np.insert(old, at, new[order]) for old, new in
            ((self.keys, keys), (self.rank, rank), (self.uid, uid), (self.idx, idx)))
        return keys[order]

    def compact(self) -> None:
        """Merge the pending rows in and sweep the dropped ones out: afterwards every row
        is a held observation."""
        self._touched.append(self._merge_pending())
        if self._dropped_rows:
            keep = self.rank != DROPPED
            self.keys, self.rank, self.uid, self.idx = (
                a[keep] for a in (self.keys, self.rank, self.uid, self.idx))
            self._dropped_rows = 0

    def first_observers(self, submap_of_uid: np.ndarray) -> FirstObservers:
        """Each key added or dropped since the last call, judged again: the smallest rank,
        then the smallest (submap id, index) among rows of equal rank (one robot's).
        `submap_of_uid[u]` is part u's submap id."""
        self._touched.append(self._merge_pending())
        touched = unique_sorted(np.concatenate(self._touched))
        self._touched = []
        lo = np.searchsorted(self.keys, touched, "left")
        n = np.searchsorted(self.keys, touched, "right") - lo
        out = FirstObservers(touched, np.zeros(touched.size, bool),
                             np.full(touched.size, DROPPED), np.zeros(touched.size, np.int32),
                             np.zeros(touched.size, np.int32))
        some = np.flatnonzero(n > 0)
        if some.size:
            rows = _ranges(lo[some], n[some])
            winner, rank = self._winners(rows, n[some], submap_of_uid)
            out.held[some] = rank != DROPPED
            out.rank[some], out.uid[some], out.idx[some] = rank, self.uid[winner], \
                self.idx[winner]
        if self._dropped_rows > self.keys.size // 4:
            self.compact()
        return out

    def _winners(self, rows: np.ndarray, size: np.ndarray, submap_of_uid: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        """(row of each group's first observer, its rank) of `rows`, consecutive groups of
        one key each, `size` rows long."""
        rank = self.rank[rows]
        start = np.cumsum(size) - size
        lowest = np.minimum.reduceat(rank, start)
        earliest = rank == np.repeat(lowest, size)
        count = np.add.reduceat(earliest.astype(np.int32), start)
        cand_all = np.flatnonzero(earliest)  # each key's earliest rows, key by key
        head = np.cumsum(count) - count
        winner = rows[cand_all[head]]
        tied = np.flatnonzero((count > 1) & (lowest != DROPPED))
        if tied.size:
            m = count[tied]
            seg = np.cumsum(m) - m
            cand = rows[cand_all[np.repeat(head[tied] - seg, m) + np.arange(int(m.sum()))]]
            place = (submap_of_uid[self.uid[cand]].astype(np.int64) << 32) + self.idx[cand]
            best = place == np.repeat(np.minimum.reduceat(place, seg), m)
            winner[tied] = cand[best]  # (submap id, index) is unique within one robot
        return winner, lowest
