"""The column-bit-mask neighbourhood sums (the fast from-scratch Alg. 1) against references."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from services.edge_server.ball_sums import ball_sums, fits
from services.edge_server.frontiers3d import ball_offsets, density_variance, gather_sums


def random_cloud(n: int, seed: int, z_span: int = 90) -> np.ndarray:
    """Unique (≈n, 3) lattice indices: dense clumps and scattered voxels, negative indices
    included, spanning several z bands of `ball_sums` (26 cells each at r = 3)."""
    rng = np.random.default_rng(seed)
    centres = rng.integers([-20, -15, -5], [20, 15, z_span], (4, 3))
    clumps = centres[rng.integers(0, 4, n)] + rng.integers(-2, 3, (n, 3))
    scattered = rng.integers([-25, -20, -8], [25, 20, z_span + 3], (n // 4, 3))
    return np.unique(np.concatenate([clumps, scattered]), axis=0)


def kdtree_sums(idx: np.ndarray, radius_vox: float) -> np.ndarray:
    """(5, N) [ρ, Σo, Σ|o|²] by a plain per-voxel KD-tree neighbourhood loop."""
    pts = idx.astype(float)
    tree = cKDTree(pts)
    out = np.zeros((5, len(idx)), np.int64)
    for i, nb in enumerate(tree.query_ball_point(pts, radius_vox + 1e-9)):
        o = idx[nb] - idx[i]
        out[:, i] = [len(nb), *o.sum(0), (o**2).sum()]
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ball_sums_equal_a_kdtree_loop(seed: int) -> None:
    idx = random_cloud(300, seed)
    offsets = ball_offsets(3.0)
    assert fits(offsets)
    got = ball_sums(idx, offsets)
    assert np.array_equal(got, kdtree_sums(idx, 3.0))
    assert got[0].max() > 20 and got[0].min() == 1  # clumps and isolated voxels both occur


@pytest.mark.parametrize("radius", [0.0, 1.0, 1.5, 2.0, 2.5, 2.9999999999999996, 3.0])
def test_ball_sums_equal_the_gather_path_for_every_small_radius(radius: float) -> None:
    idx = random_cloud(2000, 7, z_span=60)
    offsets = ball_offsets(radius)
    assert np.array_equal(ball_sums(idx, offsets), gather_sums(idx, offsets))
    # order of the voxels does not matter
    perm = np.random.default_rng(0).permutation(len(idx))
    assert np.array_equal(ball_sums(idx[perm], offsets), gather_sums(idx, offsets)[:, perm])


def test_density_variance_is_the_kdtree_variance_and_falls_back_beyond_r3() -> None:
    idx = random_cloud(250, 4)
    for radius in (3.0, 3.5):  # 3.5: K = 179, too many for the packed fields: gather path
        assert fits(ball_offsets(radius)) == (radius == 3.0)
        rho, var = density_variance(idx, radius)
        pts = idx.astype(float)
        tree = cKDTree(pts)
        for i, nb in enumerate(tree.query_ball_point(pts, radius + 1e-9)):
            assert rho[i] == len(nb)
            want = ((pts[nb] - pts[nb].mean(0)) ** 2).sum(1).mean()
            assert var[i] == pytest.approx(want, abs=1e-9)


def test_single_voxel_flat_layer_and_empty() -> None:
    offsets = ball_offsets(3.0)
    assert np.array_equal(ball_sums(np.array([[5, -7, 100]]), offsets)[:, 0], [1, 0, 0, 0, 0])
    layer = np.c_[np.mgrid[0:9, 0:9].reshape(2, -1).T, np.zeros(81, np.int64)]
    assert np.array_equal(ball_sums(layer, offsets), gather_sums(layer, offsets))
    assert ball_sums(np.zeros((0, 3), np.int64), offsets).shape == (5, 0)
    with pytest.raises(ValueError):
        ball_sums(layer, ball_offsets(4.0))
