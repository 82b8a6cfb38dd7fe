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

The rows live in two sorted runs: new rows are merged into a small recent run, which is
folded into the main one only once it holds `FOLD_SHARE` of the main run's rows, so a
correction copies the recent rows rather than every row of the mission (each merge into one
sorted table copied all of it: in an AWS-house mission 14 corrections spent 1.1 s so). A
key's rows are those of both runs; the answers do not depend on which run holds a row.

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


FOLD_SHARE = 0.25  # the recent run is folded into the main one at this share of its rows


class _Run:
    """Rows (world key, rank, part uid, index in part) sorted by key."""

    def __init__(self) -> None:
        self.keys = np.zeros(0, np.int64)
        self.rank = np.zeros(0, np.int64)
        self.uid = np.zeros(0, np.int32)
        self.idx = np.zeros(0, np.int32)

    @property
    def size(self) -> int:
        return int(self.keys.size)

    def insert(self, keys: np.ndarray, rank: np.ndarray, uid: np.ndarray,
               idx: np.ndarray) -> None:
        """Merge rows sorted by key in."""
        at = np.searchsorted(self.keys, keys)
        self.keys, self.rank, self.uid, self.idx = (
            np.insert(old, at, new) for old, new in
            ((self.keys, keys), (self.rank, rank), (self.uid, uid), (self.idx, idx)))

    def spans(self, touched: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(first row, row count) of each of the sorted keys `touched`."""
        lo = np.searchsorted(self.keys, touched, "left")
        return lo, np.searchsorted(self.keys, touched, "right") - lo

    def drop(self, uid: int, touched: np.ndarray) -> int:
        """Mark the held rows of part `uid` under the keys `touched` dropped; how many."""
        rows = _ranges(*self.spans(touched))
        rows = rows[(self.uid[rows] == uid) & (self.rank[rows] != DROPPED)]
        self.rank[rows] = DROPPED
        return int(rows.size)

    def take(self, keep: np.ndarray) -> None:
        self.keys, self.rank, self.uid, self.idx = (
            a[keep] for a in (self.keys, self.rank, self.uid, self.idx))


class ObservationTable:
    """Every observation as a row (world key, rank, part uid, index in part), in a main and a
    recent run sorted by key; rank is first tick × 256 + robot (robots are uint8), or
    `DROPPED`."""

    def __init__(self) -> None:
        self.main, self.recent = _Run(), _Run()
        self._pending: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self._touched: list[np.ndarray] = []  # keys that lost rows since the last judgement
        self._dropped_rows = 0

    @property
    def keys(self) -> np.ndarray:
        """The main run's keys (every row's once `compact` ran)."""
        return self.main.keys

    def __len__(self) -> int:
        """Observations held (dropped rows not counted)."""
        return (self.main.size + self.recent.size - self._dropped_rows
                + sum(p[0].size for p in self._pending))

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
            self._dropped_rows += self.main.drop(uid, touched) + self.recent.drop(uid, touched)
            self._touched.append(touched)

    def _merge_pending(self) -> np.ndarray:
        """Merge the pending rows into the recent run (and that into the main one once it is
        large enough); their keys, sorted."""
        if not self._pending:
            return np.zeros(0, np.int64)
        keys, rank, uid, idx = (np.concatenate(a) for a in zip(*self._pending, strict=True))
        self._pending = []
        order = np.argsort(keys)
        self.recent.insert(keys[order], rank[order], uid[order], idx[order])
        if self.recent.size > FOLD_SHARE * self.main.size:
            self._fold()
        return keys[order]

    def _fold(self) -> None:
        r = self.recent
        self.main.insert(r.keys, r.rank, r.uid, r.idx)
        self.recent = _Run()

    def compact(self) -> None:
        """Merge the pending and recent rows in and sweep the dropped ones out: afterwards
        the main run holds every row, and every row is a held observation."""
        self._touched.append(self._merge_pending())
        self._fold()
        if self._dropped_rows:
            self.main.take(self.main.rank != DROPPED)
            self._dropped_rows = 0

    def first_observers(self, submap_of_uid: np.ndarray) -> FirstObservers:
        """Each key added or dropped since the last call, judged again: the smallest rank,
        then the smallest (submap id, index) among rows of equal rank (one robot's).
        `submap_of_uid[u]` is part u's submap id."""
        self._touched.append(self._merge_pending())
        touched = unique_sorted(np.concatenate(self._touched))
        self._touched = []
        out = FirstObservers(touched, np.zeros(touched.size, bool),
                             np.full(touched.size, DROPPED), np.zeros(touched.size, np.int32),
                             np.zeros(touched.size, np.int32))
        lo_m, n_m = self.main.spans(touched)
        lo_r, n_r = self.recent.spans(touched)
        n = n_m + n_r
        some = np.flatnonzero(n > 0)
        if some.size:
            rank, uid, idx = self._gather(lo_m[some], n_m[some], lo_r[some], n_r[some])
            winner, lowest = _winners(rank, uid, idx, n[some], submap_of_uid)
            out.held[some] = lowest != DROPPED
            out.rank[some], out.uid[some], out.idx[some] = lowest, uid[winner], idx[winner]
        if self._dropped_rows > (self.main.size + self.recent.size) // 4:
            self.compact()
        return out

    def _gather(self, lo_m: np.ndarray, n_m: np.ndarray, lo_r: np.ndarray, n_r: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rank, uid, idx) of each key's rows of both runs, key after key (main's first)."""
        n = n_m + n_r
        start = np.cumsum(n) - n
        at_m = _ranges(start, n_m)
        at_r = _ranges(start + n_m, n_r)
        rows_m, rows_r = _ranges(lo_m, n_m), _ranges(lo_r, n_r)
        total = int(n.sum())
        out = []
        for name, dtype in (("rank", np.int64), ("uid", np.int32), ("idx", np.int32)):
            col = np.empty(total, dtype)
            col[at_m] = getattr(self.main, name)[rows_m]
            col[at_r] = getattr(self.recent, name)[rows_r]
            out.append(col)
        return out[0], out[1], out[2]


def _winners(rank: np.ndarray, uid: np.ndarray, idx: np.ndarray, size: np.ndarray,
             submap_of_uid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position of each group's first observer, its rank) among rows given as consecutive
    groups of one key each, `size` rows long."""
    start = np.cumsum(size) - size
    lowest = np.minimum.reduceat(rank, start)
    earliest = rank == np.repeat(lowest, size)
    count = np.add.reduceat(earliest.astype(np.int32), start)
    cand_all = np.flatnonzero(earliest)  # each key's earliest rows, key by key
    head = np.cumsum(count) - count
    winner = cand_all[head]
    tied = np.flatnonzero((count > 1) & (lowest != DROPPED))
    if tied.size:
        m = count[tied]
        seg = np.cumsum(m) - m
        cand = cand_all[np.repeat(head[tied] - seg, m) + np.arange(int(m.sum()))]
        place = (submap_of_uid[uid[cand]].astype(np.int64) << 32) + idx[cand]
        best = place == np.repeat(np.minimum.reduceat(place, seg), m)
        winner[tied] = cand[best]  # (submap id, index) is unique within one robot
    return winner, lowest
