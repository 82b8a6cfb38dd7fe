"""Geometry of a 2D grid in the world frame: row = y index, col = x index."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class GridSpec:
    """A (height, width) grid whose cell (0, 0) has its outer corner at (origin_x, origin_y)."""

    origin_x: float
    origin_y: float
    resolution_m: float
    height: int
    width: int

    @property
    def shape(self) -> tuple[int, int]:
        return (self.height, self.width)

    def cell_of(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) world xy → (N, 2) int64 (row, col); may lie outside the grid."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        col = np.floor((xy[:, 0] - self.origin_x) / self.resolution_m)
        row = np.floor((xy[:, 1] - self.origin_y) / self.resolution_m)
        return np.stack([row, col], axis=1).astype(np.int64)

    def centre_of(self, rc: np.ndarray) -> np.ndarray:
        """(N, 2) (row, col) → (N, 2) world xy of the cell centres."""
        rc = np.asarray(rc, dtype=np.float64).reshape(-1, 2)
        x = self.origin_x + (rc[:, 1] + 0.5) * self.resolution_m
        y = self.origin_y + (rc[:, 0] + 0.5) * self.resolution_m
        return np.stack([x, y], axis=1)

    def contains(self, rc: np.ndarray) -> np.ndarray:
        """(N,) bool: which (row, col) lie inside the grid."""
        rc = np.asarray(rc).reshape(-1, 2)
        return (
            (rc[:, 0] >= 0) & (rc[:, 0] < self.height) & (rc[:, 1] >= 0) & (rc[:, 1] < self.width)
        )

    @staticmethod
    def covering(
        xy_min: np.ndarray, xy_max: np.ndarray, resolution_m: float, margin_m: float = 0.0
    ) -> GridSpec:
        """The smallest grid aligned to multiples of the resolution that covers a box."""
        lo = np.floor((np.asarray(xy_min) - margin_m) / resolution_m) * resolution_m
        hi = np.ceil((np.asarray(xy_max) + margin_m) / resolution_m) * resolution_m
        width, height = np.maximum(np.round((hi - lo) / resolution_m).astype(int), 1)
        return GridSpec(float(lo[0]), float(lo[1]), resolution_m, int(height), int(width))
