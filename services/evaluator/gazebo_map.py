"""Check the 2D truth against a ROS map_server map (PGM + YAML), e.g. the AWS house's Gazebo map."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from services.common.grid import GridSpec
from services.evaluator.free_space import FreeGrid
from services.evaluator.metrics import resample_mask


@dataclass(frozen=True)
class RosMap:
    """A map_server map as world-aligned masks (row 0 = lowest y, unlike the PGM)."""

    spec: GridSpec
    free: np.ndarray  # (H, W) bool
    occupied: np.ndarray  # (H, W) bool


def read_pgm(path: Path) -> np.ndarray:
    """(H, W) uint8 of a binary (P5) 8-bit PGM; comment lines allowed."""
    data = Path(path).read_bytes()
    fields: list[bytes] = []
    pos = 0
    while len(fields) < 4:
        line_end = data.index(b"\n", pos)
        line = data[pos:line_end].split(b"#")[0]
        fields += line.split()
        pos = line_end + 1
    if fields[0] != b"P5" or int(fields[3]) > 255:
        raise ValueError(f"{path}: not an 8-bit binary PGM")
    width, height = int(fields[1]), int(fields[2])
    return np.frombuffer(data, dtype=np.uint8, count=width * height, offset=pos).reshape(
        height, width
    )


def load_ros_map(yaml_path: Path) -> RosMap:
    """Load a map_server YAML + PGM with its thresholds (trinary interpretation)."""
    yaml_path = Path(yaml_path)
    meta = yaml.safe_load(yaml_path.read_text())
    pixels = read_pgm(yaml_path.parent / meta["image"])[::-1]  # PGM row 0 is the top (max y)
    occ_prob = pixels / 255.0 if meta.get("negate", 0) else (255 - pixels.astype(float)) / 255.0
    spec = GridSpec(
        float(meta["origin"][0]), float(meta["origin"][1]), float(meta["resolution"]),
        pixels.shape[0], pixels.shape[1],
    )
    return RosMap(
        spec=spec,
        free=occ_prob < float(meta["free_thresh"]),
        occupied=occ_prob > float(meta["occupied_thresh"]),
    )


def compare_with_ros_map(truth: FreeGrid, ros_map: RosMap) -> dict[str, float]:
    """Agreement of the 2D truth with a map_server map, aligned by world coordinates.

    - free_iou: |truth free ∩ map free| / |truth free ∪ map free|.
    - agreement_pct: over the cells the map knows (free or occupied), % where "truth free"
      equals "map free".
    - truth_free_m2, map_free_m2: the two free areas.
    """
    map_free = resample_mask(ros_map.free, ros_map.spec, truth.spec)
    map_known = map_free | resample_mask(ros_map.occupied, ros_map.spec, truth.spec)
    cell_m2 = truth.spec.resolution_m**2
    inter = np.count_nonzero(truth.free & map_free)
    union = np.count_nonzero(truth.free | map_free)
    agree = np.count_nonzero((truth.free == map_free) & map_known)
    # Map free cells outside the truth's grid count against the IoU too.
    outside = np.count_nonzero(ros_map.free) - np.count_nonzero(map_free)
    return {
        "free_iou": inter / max(union + outside, 1),
        "agreement_pct": 100.0 * agree / max(np.count_nonzero(map_known), 1),
        "truth_free_m2": float(truth.free.sum()) * cell_m2,
        "map_free_m2": float(ros_map.free.sum()) * ros_map.spec.resolution_m**2,
    }
