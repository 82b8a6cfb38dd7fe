"""The agent's keyframe pose graph: loop closures pull a drifted chain back, a false closure
is rejected, and an agent with the back end on keeps its submaps and front end together."""

from __future__ import annotations

import numpy as np

from schemas import decode, encode
from schemas.messages import Submap
from services.common.geometry import T_from_xyyaw, invert, xyyaw_from_T
from services.common.pose_graph import info_diag
from services.robot_agent.agent import AgentCore
from services.robot_agent.config import AgentConfig
from services.robot_agent.keyframe_graph import KeyframeGraph, LoopClosure, LoopParams
from tests.test_agent_core import _run
from tests.test_edge_merger import crop, scene

# A tour of the 6 × 4 m room that comes back to where it started.
TOUR = [(1.5, 2.0, 0.0), (2.7, 1.6, 0.2), (3.9, 1.6, 0.4), (4.8, 2.2, 1.6), (4.0, 2.9, 2.8),
        (2.8, 2.8, 3.0), (1.8, 2.4, -2.8), (1.6, 2.0, -0.2), (2.6, 1.7, 0.1)]


def _error(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    dx, dy, dyaw = xyyaw_from_T(invert(T_true) @ T_est)
    return float(np.hypot(dx, dy)), abs(float(dyaw))


def _drifted(k: int) -> np.ndarray:
    """The front end's estimate of keyframe k: 0.5° and 1.7 cm more off at every keyframe."""
    drift = T_from_xyyaw(0.015 * k, -0.008 * k, np.radians(0.5) * k)
    return T_from_xyyaw(*TOUR[0]) @ drift @ invert(T_from_xyyaw(*TOUR[0])) @ \
        T_from_xyyaw(*TOUR[k])


def test_a_drifted_chain_is_pulled_back_by_loop_closures() -> None:
    world = scene()
    graph = KeyframeGraph(LoopParams())
    truth = [T_from_xyyaw(*p) for p in TOUR]
    moved: dict[int, np.ndarray] = {}
    for k in range(len(TOUR)):
        graph.add_keyframe(k, _drifted(k))  # the front end's poses, never re-anchored
        if k:
            moved.update(graph.close(k - 1, crop(world, truth[k - 1])))
    moved.update(graph.close(len(TOUR) - 1, crop(world, truth[-1])))
    before = _error(_drifted(len(TOUR) - 1), truth[-1])
    after = _error(graph.keyframes[len(TOUR) - 1].T_loc_kf, truth[-1])
    assert before[0] > 0.1 and before[1] > np.radians(3.5)
    assert graph.stats()["closures"] >= 3  # confirmed in pairs: the last may still wait
    # closures (σ 3 cm) pull the 14 cm / 4° end back to a quarter of it, not to zero: the
    # front end's odometry edges claim 1 cm + 2 %/m, more certain than this synthetic drift
    assert after[0] < 0.25 * before[0] and after[1] < 0.25 * before[1], (before, after)
    assert after[0] < 0.04 and after[1] < np.radians(1.0), (before, after)
    assert len(moved) >= 3  # reported so the agent can move its submaps


def test_a_false_loop_closure_is_rejected() -> None:
    truth = [T_from_xyyaw(*p) for p in TOUR]
    graph = KeyframeGraph(LoopParams())
    for k, T in enumerate(truth):
        graph.add_keyframe(k, T)
    info = info_diag([0.002] * 3, [0.01] * 3)
    for a, b in [(0, 7), (1, 6), (0, 6)]:  # true closures
        graph.closures.append(LoopClosure(a, b, invert(truth[a]) @ truth[b], info))
    wrong = invert(truth[2]) @ truth[6] @ T_from_xyyaw(0.5, 0.3, np.radians(12))
    graph.closures.append(LoopClosure(2, 6, wrong, info))
    graph.solve()
    assert graph.dropped == 1
    for k, T in enumerate(truth):
        dt, dr = _error(graph.keyframes[k].T_loc_kf, T)
        assert dt < 0.01 and dr < np.radians(0.2), (k, dt, dr)


def test_agent_with_back_end_keeps_submaps_and_sends_pose_updates_on_the_wire() -> None:
    core = AgentCore(AgentConfig(loop_closure=True), 0, 0.1)
    assert core.back_end is not None
    _, ticks = _run(core, 120)
    seqs = []
    for outs in ticks:
        for o in outs:
            if o.topic == "submap":
                msg = decode(encode(o.message), Submap)
                seqs.append(msg.seq)
    assert seqs == list(range(len(seqs)))
    graph = core.back_end.graph
    assert graph.stats()["keyframes"] == len(core.mapper.submaps()) >= 3
    for sub in core.mapper.submaps():  # the agent's submaps sit where the graph put them
        dt, dr = _error(sub.pose(), graph.keyframes[sub.submap_id].T_reported)
        assert dt < 1e-9 and dr < 1e-9
