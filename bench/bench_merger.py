"""Map-merger update time for 3, 6 and 24 robots; prints a markdown table.

Scene: a room of 8 m × 5 m per robot (floor, walls, random boxes at random yaw), sampled at
2 cm. Each robot drives a loop of keyframes 1.5 m apart; a submap is its keyframe's 3.5 m crop
in the keyframe frame, reported with a drift growing 1 cm and 0.3° per keyframe. The merger
first catches up on `--submaps` keyframes per robot (every candidate pair registered), then
each timed step adds one new keyframe per robot (what arrives between two edge ticks) and runs
`MapMerger.update`: new nodes and odometry edges, the candidate search over every closed pair,
at most `max_registrations` registrations (1 by default), and the robust LM (Huber, Cauchy,
gate). Reported: medians of the step with its one registration, the step without any (LM +
bookkeeping), and a registration alone.

Run: .venv/bin/python bench/bench_merger.py [--robots 3 6 24] [--submaps 6] [--steps 5]
"""

from __future__ import annotations

import argparse
import logging
import statistics
import time

import numpy as np

from schemas.messages import Submap
from services.common.geometry import T_from_xyyaw, invert, transform_points
from services.edge_server.merger import MapMerger, MergerParams
from services.edge_server.submap_store import SubmapStore

log = logging.getLogger("bench_merger")
V = 0.05


def room(width: float, depth: float, rng: np.random.Generator, s: float = 0.02) -> np.ndarray:
    u, v, h = np.arange(0, width, s), np.arange(0, depth, s), np.arange(0, 1.5, s)
    parts = [np.stack(np.meshgrid(u, v, [0.0]), -1).reshape(-1, 3)]
    parts += [np.stack(np.meshgrid(u, [y], h), -1).reshape(-1, 3) for y in (0.0, depth)]
    parts += [np.stack(np.meshgrid([x], v, h), -1).reshape(-1, 3) for x in (0.0, width)]
    for _ in range(int(width * depth / 3)):
        size = rng.uniform([0.2, 0.2, 0.3], [0.8, 0.8, 1.2])
        g = np.stack(np.meshgrid(*(np.arange(0, d, s) for d in size)), -1).reshape(-1, 3)
        box = g[((g == 0) | (g >= size - s)).any(axis=1)]
        parts.append(transform_points(T_from_xyyaw(*rng.uniform([0.5, 0.5, -3], [width - 0.5,
                                                                  depth - 0.5, 3])), box))
    return np.concatenate(parts)


def keyframes(robot: int, n: int, width: float, depth: float) -> list[np.ndarray]:
    """A loop around the room, each robot starting at its own phase."""
    out = []
    for k in range(n):
        a = 2 * np.pi * (k * 1.5 / (2 * (width + depth)) + robot / 7)
        x = width / 2 + 0.35 * width * np.cos(a)
        y = depth / 2 + 0.35 * depth * np.sin(a)
        out.append(T_from_xyyaw(x, y, a + np.pi / 2))
    return out


def submap(world: np.ndarray, robot: int, k: int, T: np.ndarray) -> Submap:
    near = np.linalg.norm(world[:, :2] - T[:2, 3], axis=1) < 3.5
    drift = T_from_xyyaw(0.01 * k, -0.005 * k, np.deg2rad(0.3) * k)
    mm = np.round(transform_points(invert(T), world[near]) * 1000).astype(np.int16)
    mm = np.unique(mm // 50 * 50 + 25, axis=0)  # 5 cm voxel centres, as agents send them
    n = len(mm)
    return Submap(robot_id=robot, submap_id=k, seq=k, tick=10 * k + 1, stamp_ns=0,
                  T_world_submap=drift @ T, points_mm=mm.T.copy(),
                  colors=np.full((n, 3), 128, np.uint8), counts=np.ones(n, np.uint16),
                  free_cells=np.zeros((2, 0), np.int16), cell_m=V)


def run(robots: int, submaps: int, steps: int) -> dict[str, float]:
    rng = np.random.default_rng(robots)
    width, depth = 8.0 * max(1, robots // 3), 5.0 * min(robots, 3) / 3 + 3
    world = room(width, depth, rng)
    poses = {r: keyframes(r, submaps + steps + 1, width, depth) for r in range(robots)}
    store = SubmapStore(V)
    merger = MapMerger(V, MergerParams(max_registrations=1))
    for k in range(submaps):
        for r in range(robots):
            store.apply(submap(world, r, k, poses[r][k]))
    while True:  # catch up: register every pending pair
        before = len(merger.registrations)
        for key, T in merger.update(store).items():
            store.set_pose(key, T)
        if len(merger.registrations) == before and merger.estimates:
            break
    with_reg, without_reg, reg_only = [], [], []
    for k in range(submaps, submaps + steps):
        for r in range(robots):
            store.apply(submap(world, r, k, poses[r][k]))
        before = len(merger.registrations)
        t0 = time.perf_counter()
        changed = merger.update(store)
        dt = time.perf_counter() - t0
        (with_reg if len(merger.registrations) > before else without_reg).append(dt)
        for key, T in changed.items():
            store.set_pose(key, T)
    closed = [sm for sm in store.ordered() if sm.submap_id < submaps]
    a, b = closed[0], next(sm for sm in closed if sm.robot_id != closed[0].robot_id)
    for _ in range(3):
        t0 = time.perf_counter()
        merger._register(a, b)
        reg_only.append(time.perf_counter() - t0)
    med = {name: 1000 * statistics.median(v) if v else float("nan")
           for name, v in (("with", with_reg), ("without", without_reg), ("reg", reg_only))}
    med["nodes"] = len(merger.estimates)
    med["edges"] = sum(e is not None for e in merger.registrations.values())
    return med


def main() -> None:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    ap = argparse.ArgumentParser()
    ap.add_argument("--robots", type=int, nargs="+", default=[3, 6, 24])
    ap.add_argument("--submaps", type=int, default=6)
    ap.add_argument("--steps", type=int, default=5)
    args = ap.parse_args()
    log.info("| robots | nodes | registration edges | update incl. 1 registration (ms) | "
             "update, no registration (ms) | one registration (ms) |\n|---|---|---|---|---|---|")
    for n in args.robots:
        m = run(n, args.submaps, args.steps)
        log.info("| %d | %d | %d | %.1f | %.1f | %.1f |", n, m["nodes"], m["edges"], m["with"],
                 m["without"], m["reg"])


if __name__ == "__main__":
    main()
