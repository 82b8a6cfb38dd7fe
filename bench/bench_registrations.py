"""Which inter-robot submap registrations can the merger trust? Measured against the truth.

For each recording (`bench_agent_replay.py record` folders), every submap the agents sent is
placed at its reported pose; the candidate pairs the merger would consider (different robots,
world boxes overlapping by ≥ 0.5 m³, ≥ 200 points) are taken largest box overlap first, up to
`--pairs`, and each is registered from its reported relative pose exactly as the merger does
(`services.common.registration`, coarse then fine GICP). Per pair: the precheck share (source
points within 0.25 m of a target point before registering), the GICP residual per inlier, the
planar condition, the shift from the estimate, and the true error of the result (the
submaps' ground-truth poses, `bench_merger_replay.truth_of`).

Prints, for the pairs that pass today's tests (converged, inlier share, shift and turn
limits): how many are bad (> 5 cm from the truth), harmful (≥ 2 cm further from the truth than
the reports were), helpful (≥ 2 cm nearer), and what each gate keeps of them; then what the
precheck would have set aside of the pairs that pass.

    .venv/bin/python bench/bench_registrations.py /tmp/rec_aws0 /tmp/rec_house0 --pairs 500
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
import small_gicp  # noqa: E402
from bench_merger_replay import submaps_of, truth_of  # noqa: E402
from gtsam import Pose3  # noqa: E402

from schemas.keys import Keys  # noqa: E402
from services.common.arrays import column_extremes  # noqa: E402
from services.common.geometry import invert  # noqa: E402
from services.common.registration import (  # noqa: E402
    Prepared,
    RegistrationParams,
    planar_condition,
    prepare,
    world_box,
)
from services.config import load_config  # noqa: E402
from services.edge_server.merger import merger_params  # noqa: E402
from services.edge_server.submap_store import StoredSubmap, SubmapStore  # noqa: E402

# ruff: noqa: N806 (T_a_b names)

PRECHECK_M = 0.25
GATES = {  # name → (max shift m, max residual per inlier, max planar condition)
    "today (shift 0.5 m)": (0.5, np.inf, np.inf),
    "shift 0.25 m": (0.25, np.inf, np.inf),
    "residual 0.015": (0.5, 0.015, np.inf),
    "condition 20": (0.5, np.inf, 20.0),
    "shift 0.25 + residual 0.015 + condition 20": (0.25, 0.015, 20.0),
    "shift 0.25 + residual 0.012 + condition 10": (0.25, 0.012, 10.0),
}


def pair_row(a: StoredSubmap, b: StoredSubmap, pa: Prepared, pb: Prepared,
             truth: dict, p: RegistrationParams) -> dict[str, float]:
    """One registration of b onto a from the reports, its features and its true error."""
    T0 = invert(a.T_reported) @ b.T_reported
    src = np.asarray(pb.fine[0].points())[:, :3]
    _, d2 = pa.fine[1].batch_nearest_neighbor_search(src @ T0[:3, :3].T + T0[:3, 3],
                                                     num_threads=1)
    coarse = small_gicp.align(pa.coarse[0], pb.coarse[0], pa.coarse[1], T0,
                              registration_type="GICP", max_correspondence_distance=p.max_corr_m,
                              num_threads=1, max_iterations=p.max_iterations)
    res = small_gicp.align(pa.fine[0], pb.fine[0], pa.fine[1], coarse.T_target_source,
                           registration_type="GICP", max_correspondence_distance=p.fine_corr_m,
                           num_threads=1, max_iterations=p.max_iterations)
    step = Pose3.Logmap(Pose3(T0).between(Pose3(res.T_target_source)))
    T_true = invert(truth[a.key]) @ truth[b.key]
    E, E0 = invert(T_true) @ res.T_target_source, invert(T_true) @ T0
    return {"ok": float(res.converged and res.num_inliers / max(pb.n_fine, 1) >= p.min_inlier_frac
                        and np.linalg.norm(step[:3]) <= p.max_turn_rad),
            "precheck": float(np.mean(np.asarray(d2) < PRECHECK_M**2)),
            "residual": res.error / max(res.num_inliers, 1), "condition": planar_condition(res.H),
            "shift": float(np.linalg.norm(step[3:])), "true": float(np.hypot(*E[:2, 3])),
            "before": float(np.hypot(*E0[:2, 3]))}


def pairs_of(rec: Path, limit: int) -> list[dict[str, float]]:
    config = load_config(rec / "run" / "config.yaml", {})
    msgs = submaps_of(rec, Keys(config.bus.prefix), config.bus.max_array_bytes)
    truth, _ = truth_of(msgs, rec / "run", config.sim.tick_s, config.agent.submap_every_ticks)
    store = SubmapStore(config.edge.voxel_m)
    for m in msgs:
        store.apply(m)
    p = merger_params(config.edge).registration
    subs = [sm for sm in store.ordered() if sm.keys.size >= 200]
    points = {sm.key: sm.points.astype(np.float64) for sm in subs}
    boxes = np.stack([world_box(np.stack(column_extremes(points[sm.key])), sm.T_reported)
                      for sm in subs])
    side = (np.minimum(boxes[:, None, 1], boxes[None, :, 1])
            - np.maximum(boxes[:, None, 0], boxes[None, :, 0]))
    overlap = np.prod(np.maximum(side, 0.0), axis=2)
    robots = np.array([sm.robot_id for sm in subs])
    rows, cols = np.nonzero(np.triu(overlap >= 0.5, 1) & (robots[:, None] != robots))
    order = np.argsort(-overlap[rows, cols], kind="stable")[:limit]
    prepared: dict = {}
    out = []
    for i in order:
        a, b = subs[rows[i]], subs[cols[i]]
        for sm in (a, b):
            if sm.key not in prepared:
                prepared[sm.key] = prepare(points[sm.key], p)
        out.append(pair_row(a, b, prepared[a.key], prepared[b.key], truth, p))
    print(f"{rec}: {len(out)} pairs of {len(rows)}", file=sys.stderr)
    return out


def report(rows: list[dict[str, float]], label: str) -> None:
    col = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    ok = col["ok"] > 0
    true, before = col["true"], col["before"]
    bad, harmful, helpful = true > 0.05, true - before > 0.02, before - true > 0.02
    print(f"\n### {label}: {len(rows)} pairs, {ok.sum()} pass the inlier and turn tests\n")
    print("| gate | kept | bad (> 5 cm) | harmful | helpful | good (< 2 cm) set aside |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, (shift, residual, condition) in GATES.items():
        g = ok & (col["shift"] <= shift) & (col["residual"] <= residual) & (
            col["condition"] <= condition)
        print(f"| {name} | {g.sum()} | {(g & bad).sum()} / {(ok & bad).sum()} | "
              f"{(g & harmful).sum()} / {(ok & harmful).sum()} | "
              f"{(g & helpful).sum()} / {(ok & helpful).sum()} | "
              f"{(ok & ~g & (true < 0.02)).sum()} / {(ok & (true < 0.02)).sum()} |")
    for frac in (0.3, 0.4, 0.5):
        asked = col["precheck"] >= frac
        print(f"\nprecheck {PRECHECK_M} m ≥ {frac}: {asked.sum()} of {len(rows)} pairs "
              f"registered, {(asked & ok).sum()} of the {ok.sum()} that pass")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("recordings", type=Path, nargs="+")
    parser.add_argument("--pairs", type=int, default=500, help="per recording, largest first")
    args = parser.parse_args()
    rows = {rec: pairs_of(rec, args.pairs) for rec in args.recordings}
    for rec, r in rows.items():
        report(r, str(rec))
    if len(rows) > 1:
        report([x for r in rows.values() for x in r], "all recordings")


if __name__ == "__main__":
    main()
