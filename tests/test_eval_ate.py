"""ATE (`ate_rmse_cm`): known answers on synthetic trajectories, and agreement with evo (its
Python API and the `evo_ape tum` command) on TUM files written by the run folder's writer."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from services.evaluator import metrics as mx
from services.evaluator import run_files as rf
from services.evaluator.evaluate import load_tracks


def _walk(n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) planar x, y, yaw of a smooth random drive."""
    yaw = np.cumsum(rng.normal(0.0, 0.1, n))
    step = 0.05 * np.c_[np.cos(yaw), np.sin(yaw)]
    return np.c_[np.cumsum(step, axis=0) + [2.0, 1.0], yaw]


def test_constant_offset_gives_its_length() -> None:
    t = np.arange(100) * 0.1
    gt = _walk(100, np.random.default_rng(0))[:, :2]
    assert mx.ate_rmse_cm(t, gt, t, gt) == 0.0
    assert mx.ate_rmse_cm(t, gt, t, gt + [0.03, 0.0]) == pytest.approx(3.0, abs=1e-9)
    assert mx.ate_rmse_cm(t, gt, t, gt + [0.018, -0.024]) == pytest.approx(3.0, abs=1e-9)


def test_no_alignment_a_shifted_estimate_keeps_its_error() -> None:
    """A rigidly moved estimate is as wrong as the move (evo with -a would report ~0)."""
    t = np.arange(50) * 0.1
    gt = _walk(50, np.random.default_rng(1))[:, :2]
    c, s = np.cos(0.2), np.sin(0.2)
    rotated = gt @ np.array([[c, -s], [s, c]]).T
    expected = 100 * np.sqrt(np.mean(np.sum((rotated - gt) ** 2, axis=1)))
    assert expected > 5.0
    assert mx.ate_rmse_cm(t, gt, t, rotated) == pytest.approx(expected, rel=1e-12)
    assert mx.ate_rmse_cm(t, gt, t, gt + [1.0, 0.0]) == pytest.approx(100.0)


def test_rms_of_varying_errors() -> None:
    t = np.arange(4) * 0.1
    gt = np.zeros((4, 3))
    est = np.array([[0.03, 0, 0], [0, 0.04, 0], [0, 0, 0.03], [0.04, 0, 0]])  # 3, 4, 3, 4 cm
    assert mx.ate_rmse_cm(t, gt, t, est) == pytest.approx(np.sqrt(12.5), abs=1e-9)


def test_association_nearest_within_max_diff() -> None:
    gt_t = np.arange(10) * 0.1
    # est jittered by a few ms, one pose 15 ms off (dropped), one missing, one before the start
    est_t = np.array([-0.5, 0.004, 0.097, 0.2, 0.315, 0.4, 0.5, 0.6, 0.7, 0.8])
    i_gt, i_est = mx.associate_stamps(gt_t, est_t)
    assert i_gt.tolist() == [0, 1, 2, 4, 5, 6, 7, 8]
    assert i_est.tolist() == [1, 2, 3, 5, 6, 7, 8, 9]
    gt = np.c_[np.arange(10.0), np.zeros(10)]
    est = np.c_[np.arange(10.0), np.zeros(10)]
    est[i_est] = gt[i_gt] + [0.0, 0.05]  # 5 cm wherever a pair exists
    est[0] = est[4] = [50.0, 50.0]  # unpaired poses must not count
    assert mx.ate_rmse_cm(gt_t, gt, est_t, est) == pytest.approx(5.0, abs=1e-9)
    assert mx.ate_rmse_cm(gt_t, gt, est_t + 1e3, est) is None  # nothing within 10 ms
    assert mx.ate_rmse_cm(gt_t, gt, np.zeros(0), np.zeros((0, 2))) is None


def test_association_iterates_the_shorter_trajectory() -> None:
    """Like evo: each pose of the trajectory with fewer poses finds its nearest partner,
    so a pose of the denser one may pair twice and the rest of it is unused."""
    gt_t = np.array([0.0, 0.1, 0.2])
    est_t = np.array([0.0, 0.004, 0.096, 0.1, 0.104, 0.3])
    i_gt, i_est = mx.associate_stamps(gt_t, est_t)
    assert i_gt.tolist() == [0, 1] and i_est.tolist() == [0, 3]
    i_est2, i_gt2 = mx.associate_stamps(est_t, gt_t)  # roles swapped: same pairs
    assert i_gt2.tolist() == [0, 1] and i_est2.tolist() == [0, 3]
    # equal distance to both neighbours → the earlier one (evo's tie rule)
    i_gt, i_est = mx.associate_stamps(np.array([0.0, 0.02]), np.array([0.01]), max_diff_s=0.02)
    assert i_gt.tolist() == [0] and i_est.tolist() == [0]
    # the nearer neighbour wins; a pose of the longer one may pair twice
    i_gt, i_est = mx.associate_stamps(np.array([1.0]), np.array([0.995, 1.004]))
    assert i_gt.tolist() == [0] and i_est.tolist() == [1]
    i_gt, i_est = mx.associate_stamps(np.array([0.5, 1.004, 1.5]), np.array([1.0, 1.008]))
    assert i_gt.tolist() == [1, 1] and i_est.tolist() == [0, 1]
    # a repeated stamp: evo's binary search takes the last copy, its linear search the first
    i_gt, _ = mx.associate_stamps(np.array([0.0, 0.1, 0.1, 0.2]), np.array([0.1]))
    assert i_gt.tolist() == [2]
    i_gt, _ = mx.associate_stamps(np.array([0.0, 0.1, 0.2, 0.1]), np.array([0.1]))
    assert i_gt.tolist() == [1]


def test_mean_over_robots_skips_robots_without_estimate() -> None:
    assert mx.mean_ate_cm([1.0, None, 3.0]) == 2.0
    assert mx.mean_ate_cm([None]) is None and mx.mean_ate_cm([]) is None


def _write_run_trajectories(run_dir: Path, robots: int) -> None:
    """GT at 10 Hz; estimates with drift and noise and some poses lost. Robot 0: at the GT
    ticks, stamps a few ms off and every 37th 15 ms off (unmatched); robot 1: 100 Hz, stamps
    as robot 0's, hence out of order (evo's linear search); robot 2: 100 Hz in order (binary
    search with several candidates within 10 ms); robot 3: exactly the GT stamps (as a run's
    files are). Robots 1 and 2 have more poses than the GT, so evo iterates the GT."""
    rng = np.random.default_rng(7)
    for robot in range(robots):
        n = 300
        gt_ns = np.arange(n, dtype=np.int64) * 100_000_000
        gt = _walk(n, rng)
        dense = robot in (1, 2)
        est_ns = np.arange(10 * n, dtype=np.int64) * 10_000_000 if dense else gt_ns
        est_xy = np.c_[np.interp(est_ns, gt_ns, gt[:, 0]), np.interp(est_ns, gt_ns, gt[:, 1])]
        drift = np.linspace(0, 0.2, len(est_ns))[:, None] * [0.6, -0.8]
        est_xy += drift + rng.normal(0, 0.01, (len(est_ns), 2))
        est_yaw = np.interp(est_ns, gt_ns, gt[:, 2])
        jitter = np.zeros(len(est_ns), dtype=np.int64)
        if robot in (0, 1):
            jitter = rng.integers(-4_000_000, 4_000_000, len(est_ns))
            jitter[::37] = 15_000_000  # beyond the 10 ms window: unmatched
        elif robot == 2:
            jitter = rng.integers(-2_000_000, 2_000_000, len(est_ns))
        keep = rng.random(len(est_ns)) > 0.1
        est_ns = (est_ns + jitter)[keep]
        assert (np.diff(est_ns) < 0).any() == (robot == 1)
        rf.write_tum(rf.gt_trajectory_path(run_dir, robot), gt_ns.tolist(),
                     [tuple(p) for p in gt])
        rf.write_tum(rf.est_trajectory_path(run_dir, robot), est_ns.tolist(),
                     [tuple(p) for p in np.c_[est_xy, est_yaw][keep]])


def _ours(run_dir: Path, robots: int) -> list[float | None]:
    gt, est = load_tracks(run_dir, robots), load_tracks(run_dir, robots, estimated=True)
    return [mx.ate_rmse_cm(tg, xg, te, xe) for (tg, xg), (te, xe) in zip(gt, est, strict=True)]


def test_agrees_with_evo_python_api(tmp_path: Path) -> None:
    from evo.core import metrics as evo_metrics
    from evo.core import sync
    from evo.tools import file_interface

    robots = 4
    _write_run_trajectories(tmp_path, robots)
    ours = _ours(tmp_path, robots)
    for robot in range(robots):
        ref = file_interface.read_tum_trajectory_file(rf.gt_trajectory_path(tmp_path, robot))
        est = file_interface.read_tum_trajectory_file(rf.est_trajectory_path(tmp_path, robot))
        ref, est = sync.associate_trajectories(ref, est)
        ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
        ape.process_data((ref, est))
        theirs_cm = 100.0 * ape.get_statistic(evo_metrics.StatisticsType.rmse)
        assert ref.num_poses < 290  # the jitter and the lost ticks really dropped pairs
        assert ours[robot] == pytest.approx(theirs_cm, abs=1e-6)
        assert ours[robot] > 2.0  # a non-trivial figure: drift reaches 20 cm


def test_agrees_with_evo_ape_command(tmp_path: Path) -> None:
    evo_ape = Path(sys.executable).parent / "evo_ape"
    assert evo_ape.exists(), f"{evo_ape} missing: pip install -e '.[dev]' installs evo"
    _write_run_trajectories(tmp_path, 2)
    ours_cm = _ours(tmp_path, 2)[1]  # robot 1: the denser estimate
    done = subprocess.run(
        [str(evo_ape), "tum", str(rf.gt_trajectory_path(tmp_path, 1)),
         str(rf.est_trajectory_path(tmp_path, 1))],
        capture_output=True, text=True, timeout=120, check=True,
    )
    match = re.search(r"^\s*rmse\s+([0-9.eE+-]+)\s*$", done.stdout, re.MULTILINE)
    assert match, done.stdout
    assert ours_cm is not None
    assert ours_cm / 100.0 == pytest.approx(float(match.group(1)), abs=1e-6)  # printed %.6f
