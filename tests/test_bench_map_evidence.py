"""bench/bench_map_evidence.py: a voxel's strongest horizontal neighbour, the ratio rule's input."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

from bench_map_evidence import neighbour_max  # noqa: E402

from services.common.voxels import pack  # noqa: E402


def _sorted(ijk: list[tuple[int, int, int]], evidence: list[int]) -> tuple[np.ndarray, ...]:
    keys = pack(np.array(ijk, np.int64))
    order = np.argsort(keys)
    return keys[order], np.array(evidence, np.int64)[order], order


def test_a_weak_layer_beside_a_strong_wall_is_outvoted_but_not_by_the_floor_below() -> None:
    wall = [(0, y, 5) for y in range(5)]  # strong face, 200 points per voxel
    ghost = [(2, y, 5) for y in range(5)]  # a weak copy two cells beside it
    leg = [(10, 0, 1)]  # a weak chair leg over a strong floor voxel
    floor = [(10, 0, 0)]
    far = [(20, 20, 5)]  # alone: no neighbour at all
    keys, evidence, order = _sorted(wall + ghost + leg + floor + far,
                                    [200] * 5 + [3] * 5 + [2] + [900] + [1])
    best = neighbour_max(keys, evidence, radius=2)
    by_input = np.empty_like(best)
    by_input[order] = best
    assert (by_input[5:10] == 200).all()  # the ghost layer sees the wall
    assert by_input[10] == 0  # the floor under the leg is not a horizontal neighbour
    assert by_input[12] == 0
    assert (evidence < 0.1 * best).sum() == 5  # only the ghost layer falls under the ratio
    assert (by_input[:5] == 200).all()  # the wall's voxels see each other, not the ghosts
    assert neighbour_max(keys, evidence, radius=1)[np.argsort(order)][5:10].max() == 3
