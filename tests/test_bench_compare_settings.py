"""bench/compare_settings.py: two settings compared seed for seed, with bootstrap intervals."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from compare_settings import compare, read_runs, relative_change, seeds_for  # noqa: E402


def write_run(folder: Path, name: str, seed: int, time_s: float, world: str = "house",
              coverage: float = 99.0, bv: float = 0.0) -> None:
    run = folder / name
    run.mkdir(parents=True)
    (run / "metrics.json").write_text(json.dumps({
        "world": world, "robots": 3, "seed": seed, "mapping_time_s": time_s,
        "total_distance_m": time_s, "coverage_3d_pct": coverage, "overlap_3d_pct": 50.0,
        "ate_rmse_cm": 1.0, "bounding_volume_pct": bv}))


def test_a_uniform_change_has_a_tight_interval_and_noise_one_that_holds_zero() -> None:
    rng = np.random.default_rng(1)
    base = rng.uniform(80, 160, 10)
    change, low, high = relative_change(base, 1.1 * base, np.random.default_rng(0))
    assert change == pytest.approx(0.1) and low == pytest.approx(0.1)
    assert high == pytest.approx(0.1)
    noisy = base * rng.uniform(0.8, 1.2, 10)  # ±20 % per mission, no change on average
    change, low, high = relative_change(base, noisy, np.random.default_rng(0))
    assert low < 0 < high and high - low > 0.05
    # the same inputs and seed give the same interval
    assert relative_change(base, noisy, np.random.default_rng(0)) == (change, low, high)
    with pytest.raises(ValueError):
        relative_change(base, noisy[:5], np.random.default_rng(0))


def test_seeds_needed_grow_with_the_spread() -> None:
    base = np.full(6, 100.0)
    tight = base * np.array([1.0, 1.01, 0.99, 1.0, 1.01, 0.99])
    loose = base * np.array([1.0, 1.2, 0.8, 1.0, 1.2, 0.8])
    assert seeds_for(base, tight, 0.02) < 5 < seeds_for(base, loose, 0.02)


def test_runs_pair_by_world_robots_and_seed(tmp_path: Path) -> None:
    for seed, t in enumerate([100.0, 120.0, 90.0]):
        write_run(tmp_path / "base", f"a{seed}", seed, t)
        write_run(tmp_path / "variant", f"b{seed}", seed, 0.9 * t,
                  coverage=97.5 if seed == 1 else 99.0, bv=0.01 * seed)
    write_run(tmp_path / "variant", "extra", 7, 50.0)  # no base run: left out, reported
    write_run(tmp_path / "base", "bookstore", 0, 80.0, world="/x/bookstore.xml")
    groups, unpaired = compare(read_runs(tmp_path / "base"), read_runs(tmp_path / "variant"))
    assert [(g.world, g.seeds) for g in groups] == [("house", [0, 1, 2])]
    b, v, change, low, high = groups[0].changes["mapping_time_s"]
    assert (b, v) == pytest.approx((310 / 3, 279 / 3))
    assert change == pytest.approx(-0.1) and low == pytest.approx(-0.1)
    assert groups[0].under_bar == (0, 1) and groups[0].worst_bv == (0.0, 0.02)
    assert unpaired == [("bookstore", 3, 0), ("house", 3, 7)]


def test_the_script_prints_the_table_and_refuses_duplicates(tmp_path: Path) -> None:
    for seed in range(3):
        write_run(tmp_path / "base", f"r{seed}", seed, 100.0 + seed)
        write_run(tmp_path / "variant", f"r{seed}", seed, 110.0 + seed)
    script = str(ROOT / "bench" / "compare_settings.py")
    out = subprocess.run([sys.executable, script, str(tmp_path / "base"),
                          str(tmp_path / "variant")], capture_output=True, text=True, check=True)
    assert "| house | 3 | 3 | 101.00 → 111.00 (+9.9 %" in out.stdout
    write_run(tmp_path / "base", "again", 0, 100.0)
    bad = subprocess.run([sys.executable, script, str(tmp_path / "base"),
                          str(tmp_path / "variant")], capture_output=True, text=True)
    assert bad.returncode != 0 and "two runs of world house" in bad.stderr
