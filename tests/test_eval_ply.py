"""PLY files of a run folder: written and read with numpy, in the layout Open3D writes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import open3d as o3d
import pytest

from services.evaluator import run_files as rf


def _open3d_bytes(path: Path, points: np.ndarray, colors: np.ndarray | None) -> bytes:
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    if colors is not None:
        cloud.colors = o3d.utility.Vector3dVector(colors.astype(np.float64) / 255.0)
    assert o3d.io.write_point_cloud(str(path), cloud, write_ascii=False)
    return path.read_bytes().replace(b"comment Created by Open3D\n", b"")


@pytest.mark.parametrize("with_colors", [False, True])
def test_write_ply_gives_open3ds_bytes(tmp_path: Path, with_colors: bool) -> None:
    rng = np.random.default_rng(0)
    points = rng.normal(size=(257, 3)) * 10
    colors = rng.integers(0, 256, size=(257, 3)).astype(np.uint8) if with_colors else None
    rf.write_ply(tmp_path / "ours.ply", points, colors)
    assert (tmp_path / "ours.ply").read_bytes() == _open3d_bytes(tmp_path / "o3d.ply", points,
                                                                  colors)


def test_read_ply_reads_open3ds_files_and_our_own(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    points = rng.uniform(-5, 5, size=(100, 3))
    colors = rng.integers(0, 256, size=(100, 3)).astype(np.uint8)
    _open3d_bytes(tmp_path / "o3d.ply", points, colors)
    np.testing.assert_array_equal(rf.read_ply(tmp_path / "o3d.ply"), points)
    rf.write_ply(tmp_path / "ours.ply", points.astype(np.float32), colors)
    np.testing.assert_array_equal(rf.read_ply(tmp_path / "ours.ply"),
                                  points.astype(np.float32).astype(np.float64))
    rf.write_ply(tmp_path / "empty.ply", np.zeros((0, 3)))
    assert rf.read_ply(tmp_path / "empty.ply").shape == (0, 3)


def test_read_ply_takes_ascii_and_float_properties_in_any_order(tmp_path: Path) -> None:
    path = tmp_path / "a.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 2\nproperty float z\n"
                    "property uchar red\nproperty float x\nproperty float y\nend_header\n"
                    "3 255 1 2\n6 0 4 5\n")
    np.testing.assert_array_equal(rf.read_ply(path), [[1, 2, 3], [4, 5, 6]])


@pytest.mark.parametrize("text", [
    "not a ply\n",
    "ply\nformat binary_big_endian 1.0\nelement vertex 1\nproperty double x\nproperty double y\n"
    "property double z\nend_header\n" + "\0" * 24,
    "ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar int x\nend_header\n1 0\n",
    "ply\nformat ascii 1.0\nelement face 0\nend_header\n",
])
def test_read_ply_rejects_what_it_cannot_read(tmp_path: Path, text: str) -> None:
    path = tmp_path / "bad.ply"
    path.write_text(text)
    with pytest.raises(ValueError):
        rf.read_ply(path)
