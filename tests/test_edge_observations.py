"""The observation table judges again only the keys whose observations changed, and its
answers equal a judgement of every held observation from scratch."""

from __future__ import annotations

import numpy as np
import pytest

from services.edge_server import observations
from services.edge_server.observations import ObservationTable


def judge_all(rows: dict[tuple[int, int], tuple[int, int, int]], submap_of_uid: np.ndarray
              ) -> dict[int, tuple[int, int, int]]:
    """key → (rank, uid, idx) of its first observer: smallest rank, then (submap id, idx)."""
    best: dict[int, tuple[int, int, int, int]] = {}
    for (uid, idx), (key, tick, robot) in rows.items():
        cand = (tick * 256 + robot, int(submap_of_uid[uid]), idx, uid)
        if key not in best or cand < best[key]:
            best[key] = cand
    return {k: (r, u, i) for k, (r, _, i, u) in best.items()}


@pytest.mark.parametrize("fold_share", [0.0, 0.25, 1e9])
def test_incremental_first_observers_equal_a_judgement_from_scratch(
        fold_share: float, monkeypatch: pytest.MonkeyPatch) -> None:
    """Whichever run holds a row: every row in the main run (0: folded at once), the
    default, and the recent run folded only by `compact` (a quarter of the rows dropped)."""
    monkeypatch.setattr(observations, "FOLD_SHARE", fold_share)
    rng = np.random.default_rng(3)
    parts = 12
    robot_of = rng.integers(0, 3, parts)
    submap_of_uid = rng.permutation(parts).astype(np.int64)  # submap ids, unique per robot
    table = ObservationTable()
    held: dict[tuple[int, int], tuple[int, int, int]] = {}  # (uid, idx) → (key, tick, robot)
    size = np.zeros(parts, int)
    state: dict[int, tuple[int, int, int]] = {}
    recent_seen = False
    for step in range(80):
        for _ in range(int(rng.integers(1, 4))):  # parts grow
            uid = int(rng.integers(parts))
            n = int(rng.integers(1, 30))
            keys = rng.integers(0, 60, n)
            ticks = np.full(n, step // 3)  # ties within a tick
            idx = np.arange(size[uid], size[uid] + n)
            table.add(keys, ticks, np.full(n, robot_of[uid]), np.full(n, uid), idx)
            held.update({(uid, int(i)): (int(k), step // 3, int(robot_of[uid]))
                         for k, i in zip(keys, idx, strict=True)})
            size[uid] += n
        if rng.random() < 0.5:  # a correction moves one or two parts: new keys for all rows
            moved = {}
            for uid in rng.choice(parts, int(rng.integers(1, 3)), replace=False).tolist():
                mine = sorted(i for u, i in held if u == uid)
                moved[uid] = np.array([held[(uid, i)][0] for i in mine], np.int64)
            table.drop(moved)
            for uid in moved:
                mine = sorted(i for u, i in held if u == uid)
                keys = rng.integers(0, 60, len(mine))
                ticks = np.array([held[(uid, i)][1] for i in mine])
                table.add(keys, ticks, np.full(len(mine), robot_of[uid]), np.full(len(mine), uid),
                          np.array(mine))
                held.update({(uid, i): (int(k), int(t), int(robot_of[uid]))
                             for i, k, t in zip(mine, keys, ticks, strict=True)})
        changed = table.first_observers(submap_of_uid)
        assert np.all(np.diff(changed.keys) > 0)
        for k, h, r, u, i in zip(changed.keys.tolist(), changed.held, changed.rank.tolist(),
                                 changed.uid.tolist(), changed.idx.tolist(), strict=True):
            if h:
                state[k] = (r, u, i)
            else:
                state.pop(k, None)
        assert state == judge_all(held, submap_of_uid), step
        assert len(table) == len(held)
        recent_seen |= table.recent.size > 0
    table.compact()
    assert table.keys.size == len(held) and np.all(np.diff(table.keys) >= 0)
    assert table.recent.size == 0
    assert recent_seen == (fold_share > 0)  # the two-run states were exercised
