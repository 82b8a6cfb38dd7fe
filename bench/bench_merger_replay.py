"""The map merger against ground truth, offline, on a recorded mission's submaps.

Replays the `Submap` messages of a `bench_agent_replay.py record` folder (a mission run with
the merger off) through `SubmapStore` + `MapMerger` at every edge tick, as the edge does, and
compares where each submap ends up with where it truly was: its ground-truth pose is the
robot's true base pose at the tick the keyframe started (found by matching the submap's
reported pose in the robot's estimated trajectory, `trajectory_R_est.tum`, at most
`submap_every_ticks` before its first message). Agents re-anchor on corrections (the newest
corrected submap's offset is applied to every later report of that robot, as
`AgentCore.on_correction` does); everything else about the mission is open loop (the robots
drive where they drove).

Prints, merger off (the reports) against on: placement error of the submaps weighted by
their voxels (mean, p90, max translation cm; mean and max yaw deg), the largest relative
error between two robots' overlapping submaps, and the registrations tried / kept /
consistent / inliers. `--set edge.KEY=VALUE` changes the edge config (merge_* fields).

    .venv/bin/python bench/bench_merger_replay.py /tmp/rec_house0 \
        [--set edge.merge_odometry_sigma_m=0.01 ...]
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
from bench_agent_replay import LOG, read_log  # noqa: E402

from schemas.codec import decode  # noqa: E402
from schemas.keys import Keys  # noqa: E402
from schemas.messages import Submap  # noqa: E402
from services.common.geometry import T_from_xyyaw, invert  # noqa: E402
from services.config import load_config  # noqa: E402
from services.edge_server.merger import MapMerger, merger_params  # noqa: E402
from services.edge_server.submap_store import SubmapKey, SubmapStore  # noqa: E402

# ruff: noqa: N806 (T_a_b names)


def read_tum(path: Path) -> np.ndarray:
    """(N, 4) stamp s, x, y, yaw from a planar TUM file."""
    rows = np.loadtxt(path, ndmin=2)
    qz, qw = rows[:, 6], rows[:, 7]
    return np.column_stack([rows[:, 0], rows[:, 1], rows[:, 2], 2 * np.arctan2(qz, qw)])


def submaps_of(rec: Path, keys: Keys, max_bytes: int) -> list[Submap]:
    prefix = f"{keys.prefix}/robot/"
    out = [decode(p, Submap, max_bytes) for k, p in read_log(rec / LOG)
           if k.startswith(prefix) and k.endswith("/submap")]
    return sorted(out, key=lambda m: m.tick)  # stable: recorded order within a tick


def truth_of(msgs: list[Submap], run: Path, tick_s: float, window: int) -> tuple[
        dict[SubmapKey, np.ndarray], float]:
    """Ground-truth pose of every submap, and the worst match residual (m) in the estimate."""
    first: dict[SubmapKey, Submap] = {}
    for m in msgs:
        first.setdefault((m.robot_id, m.submap_id), m)
    est = {r: read_tum(run / f"trajectory_{r}_est.tum") for r, _ in first}
    gt = {r: read_tum(run / f"trajectory_{r}_gt.tum") for r, _ in first}
    truth, worst = {}, 0.0
    for key, m in first.items():
        e, g = est[key[0]], gt[key[0]]
        ticks = np.round(e[:, 0] / tick_s).astype(int)
        near = np.nonzero((ticks <= m.tick) & (ticks >= m.tick - window))[0]
        T = m.T_world_submap
        yaw = np.arctan2(T[1, 0], T[0, 0])
        d = np.hypot(e[near, 1] - T[0, 3], e[near, 2] - T[1, 3]) + 0.1 * np.abs(
            np.angle(np.exp(1j * (e[near, 3] - yaw))))
        i = near[int(np.argmin(d))]
        worst = max(worst, float(d.min()))
        j = int(np.argmin(np.abs(g[:, 0] - e[i, 0])))
        truth[key] = T_from_xyyaw(g[j, 1], g[j, 2], g[j, 3])
    return truth, worst


def replay(msgs: list[Submap], merger: MapMerger | None, voxel_m: float, every: int
           ) -> SubmapStore:
    """Feed the submaps tick by tick; with a merger, correct at every edge tick."""
    store = SubmapStore(voxel_m)
    offset: dict[int, np.ndarray] = {}
    reported: dict[SubmapKey, np.ndarray] = {}  # in the mission's own (never corrected) frame
    fed = 0
    for k in range(0, msgs[-1].tick + every + 1, every):
        while fed < len(msgs) and msgs[fed].tick < k:
            m = msgs[fed]
            reported[(m.robot_id, m.submap_id)] = m.T_world_submap
            T_fix = offset.get(m.robot_id)
            # merger off in the recording: the agent's frame was the world's (T_world_loc = I)
            T_odom = m.T_world_submap if m.T_odom_submap is None else m.T_odom_submap
            store.apply(m.model_copy(update={"T_odom_submap": T_odom}) if T_fix is None
                        else m.model_copy(update={"T_world_submap": T_fix @ m.T_world_submap,
                                                  "T_odom_submap": T_odom}))
            fed += 1
        if merger is None:
            continue
        changed = merger.update(store)
        for key in sorted(changed):
            store.set_pose(key, changed[key])
        for robot in sorted({r for r, _ in changed}):
            newest = max(s for r, s in merger.estimates if r == robot)
            offset[robot] = merger.estimates[(robot, newest)] @ invert(reported[(robot, newest)])
    return store


def errors(store: SubmapStore, truth: dict[SubmapKey, np.ndarray]) -> dict[str, float]:
    keys = sorted(store.submaps)
    w = np.array([store.submaps[k].keys.size for k in keys], float)
    dt, dyaw, xy = [], [], []
    for k in keys:
        E = invert(truth[k]) @ store.submaps[k].T_world_submap
        dt.append(float(np.hypot(E[0, 3], E[1, 3])))
        dyaw.append(abs(float(np.degrees(np.arctan2(E[1, 0], E[0, 0])))))
        xy.append(truth[k][:2, 3])
    dt_a, yaw_a = np.array(dt), np.array(dyaw)
    order = np.argsort(dt_a)
    cum = np.cumsum(w[order]) / w.sum()
    # relative error between submaps of different robots within 3 m of each other
    robots = np.array([k[0] for k in keys])
    P = np.array(xy)
    off = np.array([store.submaps[k].T_world_submap[:2, 3] - truth[k][:2, 3] for k in keys])
    near = (np.linalg.norm(P[:, None] - P[None], axis=2) < 3.0) & (robots[:, None] != robots)
    rel = np.linalg.norm(off[:, None] - off[None], axis=2)[near]
    return {"mean_cm": 100 * float(np.average(dt_a, weights=w)),
            "p90_cm": 100 * float(dt_a[order][np.searchsorted(cum, 0.9)]),
            "max_cm": 100 * float(dt_a.max()),
            "yaw_mean_deg": float(np.average(yaw_a, weights=w)),
            "yaw_max_deg": float(yaw_a.max()),
            "rel_max_cm": 100 * float(rel.max()) if rel.size else 0.0}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recording", type=Path)
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args()
    overrides = dict(s.split("=", 1) for s in args.set)
    config = load_config(args.recording / "run" / "config.yaml", overrides)
    msgs = submaps_of(args.recording, Keys(config.bus.prefix), config.bus.max_array_bytes)
    truth, worst = truth_of(msgs, args.recording / "run", config.sim.tick_s,
                            config.agent.submap_every_ticks)
    every = config.sim.edge_every_ticks
    merger = MapMerger(config.edge.voxel_m, merger_params(config.edge))
    rows = {"off (reports)": errors(replay(msgs, None, config.edge.voxel_m, every), truth),
            "on": errors(replay(msgs, merger, config.edge.voxel_m, every), truth)}
    tried = len(merger.registrations)
    kept = sum(e is not None for e in merger.registrations.values())
    print(f"{len(truth)} submaps; truth matched within {100 * worst:.1f} cm; registrations "
          f"tried {tried}, kept {kept}, consistent + inliers {sum(merger.inliers.values())}")
    names = list(next(iter(rows.values())))
    print("| merger | " + " | ".join(names) + " |\n|---|" + "---:|" * len(names))
    for label, row in rows.items():
        print(f"| {label} | " + " | ".join(f"{row[n]:.2f}" for n in names) + " |")


if __name__ == "__main__":
    main()
