"""Scoring helpers and run-folder file round trips on synthetic data."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from schemas import messages as m
from services.evaluator import run_files as rf
from services.evaluator.scoring import distance_at


def test_distance_at_sums_robots_up_to_each_time() -> None:
    stamps = np.array([0.0, 1.0, 2.0])
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 2.0]])
    tracks = [(stamps, xy), (stamps, 2 * xy)]
    assert distance_at(np.array([0.0, 1.0, 1.5, 5.0]), tracks) == [0.0, 3.0, 3.0, 9.0]


def test_grid_csv_ply_round_trips(tmp_path: Path) -> None:
    cells = np.array([[-1, 0], [100, 0], [0, -1]], dtype=np.int8)
    grid = m.OccupancyGrid(tick=3, resolution_m=0.05, origin_x=-1.0, origin_y=2.5, cells=cells)
    rf.write_grid(tmp_path / "g", grid)
    back = rf.read_grid(tmp_path / "g")
    assert np.array_equal(back.cells, cells) and back.origin_y == 2.5
    rows = [{"sim_time_s": 1.0, "coverage_3d_pct": None}, {"sim_time_s": 2.0,
                                                           "coverage_3d_pct": 3.25}]
    rf.write_csv(tmp_path / "s.csv", rows, ["sim_time_s", "coverage_3d_pct"])
    assert rf.read_csv(tmp_path / "s.csv") == rows
    pts = np.random.default_rng(0).normal(size=(100, 3)).astype(np.float32)
    rf.write_ply(tmp_path / "p.ply", pts)
    assert np.array_equal(rf.read_ply(tmp_path / "p.ply"), pts.astype(np.float64))
    rf.write_ply(tmp_path / "empty.ply", np.zeros((0, 3)))
    assert rf.read_ply(tmp_path / "empty.ply").shape == (0, 3)
