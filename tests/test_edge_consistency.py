"""PCM over inter-robot registrations: a false closure is left out, a lone one waits."""

from __future__ import annotations

import numpy as np

from services.common.geometry import T_from_xyyaw, invert
from services.common.pose_graph import Between, info_diag
from services.edge_server.consistency import (
    ConsistencyMemo,
    ConsistencyParams,
    max_clique,
    select,
)
from services.edge_server.merger import MapMerger, pose_change
from tests.test_edge_merger import LOOSE, V, build_store

INFO = info_diag([0.005] * 3, [0.02] * 3)
PARAMS = ConsistencyParams()


def _scene() -> tuple[dict, dict, dict]:
    """Robot 0 and robot 1 each report four submaps; robot 1's frame is off by a fixed
    0.3 m / 5° (its start estimate), so every true edge asks for the same correction."""
    truth = {(r, k): T_from_xyyaw(1.0 * k, 0.5 * r, 0.1 * k) for r in (0, 1) for k in range(4)}
    offset = T_from_xyyaw(0.3, -0.1, np.deg2rad(5))
    reported = {key: (offset @ T if key[0] == 1 else T) for key, T in truth.items()}
    robot_of = {key: (key[0], 0) for key in truth}
    return truth, reported, robot_of


def _edge(truth: dict, a: tuple, b: tuple, wrong: np.ndarray | None = None) -> Between:
    T = invert(truth[a]) @ truth[b]
    return Between(a, b, T if wrong is None else T @ wrong, INFO, True)


def test_false_closure_left_out_of_a_consistent_set() -> None:
    truth, reported, robot_of = _scene()
    edges = [_edge(truth, (0, k), (1, k)) for k in range(3)]
    edges.append(_edge(truth, (0, 3), (1, 3), T_from_xyyaw(0.4, 0.2, 0.15)))  # wrong basin
    edges.append(_edge(truth, (1, 2), (0, 1)))  # the other way round: still the same pair
    assert select(edges, reported, robot_of, PARAMS) == [True, True, True, False, True]


def test_a_lone_closure_waits_for_a_second() -> None:
    truth, reported, robot_of = _scene()
    assert select([_edge(truth, (0, 1), (1, 1))], reported, robot_of, PARAMS) == [False]
    # two that disagree: neither is trusted
    pair = [_edge(truth, (0, 1), (1, 1)), _edge(truth, (0, 2), (1, 2), T_from_xyyaw(0.5, 0, 0))]
    assert select(pair, reported, robot_of, PARAMS) == [False, False]


def test_max_clique() -> None:
    adj = np.zeros((6, 6), bool)
    for i, j in [(0, 1), (0, 2), (1, 2), (2, 3), (3, 4), (1, 3), (0, 3), (4, 5)]:
        adj[i, j] = adj[j, i] = True
    assert max_clique(adj) == [0, 1, 2, 3]
    assert max_clique(np.zeros((3, 3), bool)) == [0]


def test_merger_rejects_an_injected_false_closure() -> None:
    drift = T_from_xyyaw(0.0, 0.0, np.deg2rad(4.0))
    drift[:2, 3] = [0.15, 0.05]
    store, truth = build_store(drift)
    merger = MapMerger(V, LOOSE)  # the chain jumps: see test_edge_merger's LOOSE
    for _ in range(16):
        for key, T in merger.update(store).items():
            store.set_pose(key, T)
    good = [e for e in merger.registrations.values() if e is not None]
    assert len(good) >= 2
    # a confident registration of robot 1's submap 3 onto robot 0's submap 0, 0.6 m / 12° off
    bad_T = invert(truth[(0, 0)]) @ truth[(1, 3)] @ T_from_xyyaw(0.6, -0.2, 0.2)
    merger.registrations[((0, 0), (1, 3))] = Between((0, 0), (1, 3), bad_T, good[0].info, True)
    merger._dirty = True
    merger.update(store)
    assert merger.inliers[((0, 0), (1, 3))] is False
    # robot 1's chain jumps by the whole drift between its first two submaps, so the
    # registrations of its first submap disagree with the others through that chain
    assert sum(merger.inliers[(e.a, e.b)] for e in good) >= 3
    for key in [(1, 1), (1, 2), (1, 3)]:
        assert pose_change(merger.estimates[key], truth[key])[0] < 0.03


def test_a_memo_gives_the_same_answers_and_sees_a_chain_pose_change() -> None:
    truth, reported, robot_of = _scene()
    edges = [_edge(truth, (0, k), (1, k)) for k in range(3)]
    edges.append(_edge(truth, (0, 3), (1, 3), T_from_xyyaw(0.4, 0.2, 0.15)))
    memo = ConsistencyMemo()
    for n in range(2, len(edges) + 1):  # one more edge per update, as the merger asks
        assert select(edges[:n], reported, robot_of, PARAMS, memo) == select(
            edges[:n], reported, robot_of, PARAMS)
    assert len(memo.tests) == 6
    # robot 1 re-reports its last submap where the "wrong" edge puts it: the memo re-tests
    moved = dict(reported)
    moved[(1, 3)] = reported[(1, 3)] @ T_from_xyyaw(0.4, 0.2, 0.15)
    want = select(edges, moved, robot_of, PARAMS)
    assert select(edges, moved, robot_of, PARAMS, memo) == want
    assert want != select(edges, reported, robot_of, PARAMS)
