"""Files of a run folder: point clouds (PLY), grids (ROS map_server PGM + YAML), TUM poses,
time series (CSV), JSON; one writer and one reader per format, and the folder's file names."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from schemas import messages as m

_EMPTY_PLY = (
    "ply\nformat ascii 1.0\nelement vertex 0\nproperty double x\nproperty double y\n"
    "property double z\nend_header\n"
)
# PLY scalar types as numpy little-endian dtypes (both the spec's names and the sized ones)
_PLY_TYPES = {"char": "i1", "uchar": "u1", "short": "<i2", "ushort": "<u2", "int": "<i4",
              "uint": "<u4", "float": "<f4", "double": "<f8", "int8": "i1", "uint8": "u1",
              "int16": "<i2", "uint16": "<u2", "int32": "<i4", "uint32": "<u4",
              "float32": "<f4", "float64": "<f8"}


def write_ply(path: Path, points_world: np.ndarray, colors: np.ndarray | None = None) -> None:
    """Binary little-endian PLY: double x, y, z (and uchar red, green, blue), the layout
    Open3D writes, with numpy: importing Open3D (and the dash/plotly its visualization module
    pulls in) cost each mission's launcher about 3 CPU-s."""
    if len(points_world) == 0:  # a robot may map nothing
        path.write_text(_EMPTY_PLY)
        return
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    with_colors = colors is not None and len(colors) > 0
    if with_colors:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    rows = np.empty(len(points_world), dtype=fields)
    xyz = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
    rows["x"], rows["y"], rows["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    if with_colors:
        rgb = np.asarray(colors).reshape(-1, 3).astype(np.uint8)
        rows["red"], rows["green"], rows["blue"] = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(rows)}"]
    header += [f"property {'double' if t == '<f8' else 'uchar'} {n}" for n, t in fields]
    path.write_bytes(("\n".join([*header, "end_header"]) + "\n").encode() + rows.tobytes())


def read_ply(path: Path) -> np.ndarray:
    """(N, 3) float64 points of a point-cloud PLY (ascii or binary little-endian, a vertex
    element with x, y, z among scalar properties: what `write_ply` and Open3D write)."""
    data = path.read_bytes()
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise ValueError(f"{path}: not a PLY file")
    body = data.index(b"\n", end) + 1
    lines = data[:body].decode("ascii").splitlines()
    fmt = next((ln.split()[1] for ln in lines if ln.startswith("format ")), "")
    elements = [ln.split() for ln in lines if ln.startswith(("element ", "property "))]
    if not elements or elements[0][:2] != ["element", "vertex"]:
        raise ValueError(f"{path}: no vertex element first")
    count, fields = int(elements[0][2]), []
    for words in elements[1:]:
        if words[0] == "element":
            break
        if words[1] == "list" or words[1] not in _PLY_TYPES:
            raise ValueError(f"{path}: unsupported vertex property {' '.join(words[1:])}")
        fields.append((words[2], _PLY_TYPES[words[1]]))
    if missing := {"x", "y", "z"} - {n for n, _ in fields}:
        raise ValueError(f"{path}: no vertex property {sorted(missing)}")
    if count == 0:
        return np.zeros((0, 3))
    if fmt == "ascii":
        rows = np.loadtxt(data[body:].decode("ascii").splitlines()[:count], ndmin=2,
                          dtype=np.float64).reshape(count, len(fields))
        names = [n for n, _ in fields]
        cols = [rows[:, names.index(a)] for a in "xyz"]
    elif fmt == "binary_little_endian":
        rows = np.frombuffer(data, dtype=fields, count=count, offset=body)
        cols = [rows[a] for a in "xyz"]
    else:
        raise ValueError(f"{path}: unsupported PLY format {fmt!r}")
    return np.stack(cols, axis=1).astype(np.float64).reshape(-1, 3)


def write_grid(stem: Path, grid: m.OccupancyGrid) -> None:
    """`stem`.pgm + `stem`.yaml in ROS map_server format (row 0 of the image = top = max y)."""
    cells = grid.cells
    image = np.full(cells.shape, 205, dtype=np.uint8)
    image[cells == 0] = 254
    image[cells >= 50] = 0
    image = image[::-1]
    header = f"P5\n{image.shape[1]} {image.shape[0]}\n255\n".encode()
    stem.with_suffix(".pgm").write_bytes(header + image.tobytes())
    meta = {
        "image": stem.with_suffix(".pgm").name,
        "resolution": float(grid.resolution_m),
        "origin": [float(grid.origin_x), float(grid.origin_y), 0.0],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
    }
    stem.with_suffix(".yaml").write_text(yaml.safe_dump(meta, sort_keys=False))


def read_grid(stem: Path) -> m.OccupancyGrid:
    """Inverse of `write_grid`."""
    meta = yaml.safe_load(stem.with_suffix(".yaml").read_text())
    raw = stem.with_suffix(".pgm").read_bytes()
    parts = raw.split(maxsplit=4)
    width, height = int(parts[1]), int(parts[2])
    image = np.frombuffer(parts[4][: width * height], dtype=np.uint8).reshape(height, width)[::-1]
    cells = np.full(image.shape, -1, dtype=np.int8)
    cells[image == 254] = 0
    cells[image == 0] = 100
    ox, oy = meta["origin"][:2]
    return m.OccupancyGrid(tick=0, resolution_m=meta["resolution"], origin_x=ox, origin_y=oy,
                           cells=cells)


def write_tum(path: Path, stamps_ns: list[int], xyyaw: list[tuple[float, float, float]]) -> None:
    """TUM trajectory: `t x y z qx qy qz qw` per line (planar: rotation about z)."""
    lines = []
    for stamp, (x, y, yaw) in zip(stamps_ns, xyyaw, strict=True):
        qz, qw = math.sin(yaw / 2.0), math.cos(yaw / 2.0)
        lines.append(f"{stamp * 1e-9:.9f} {x:.6f} {y:.6f} 0.0 0.0 0.0 {qz:.9f} {qw:.9f}")
    path.write_text("\n".join(lines) + ("\n" if lines else ""))


def read_tum(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(stamps_s (T,), xyyaw (T, 3)) from a TUM file written by `write_tum`."""
    rows = np.loadtxt(path, ndmin=2) if path.stat().st_size else np.zeros((0, 8))
    yaw = 2.0 * np.arctan2(rows[:, 6], rows[:, 7])
    return rows[:, 0], np.stack([rows[:, 1], rows[:, 2], yaw], axis=1)


def write_json(path: Path, data: dict[str, Any]) -> None:
    path.write_text(json.dumps(data, indent=2, sort_keys=False) + "\n")


def read_json(path: Path) -> dict[str, Any]:
    return json.loads(path.read_text())


def write_events(path: Path, events: list[dict[str, Any]]) -> None:
    """One JSON object per line (robot, tick, kind, ...), in the order given."""
    path.write_text("".join(json.dumps(e, sort_keys=True) + "\n" for e in events))


def read_events(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def write_csv(path: Path, rows: list[dict[str, Any]], columns: list[str]) -> None:
    """Rows as CSV; floats with 4 decimals, None as an empty cell."""
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(columns)
        for row in rows:
            writer.writerow([_cell(row.get(c)) for c in columns])


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.4f}"
    return str(value)


def read_csv(path: Path) -> list[dict[str, float | None]]:
    """Numeric CSV (as written by `write_csv`) → rows; empty cells are None."""
    with path.open(newline="") as f:
        return [
            {k: (float(v) if v not in ("", None) else None) for k, v in row.items()}
            for row in csv.DictReader(f)
        ]


def robot_map_path(run_dir: Path, robot: int) -> Path:
    return run_dir / f"robot_{robot}_map.ply"


def robot_grid_stem(run_dir: Path, robot: int) -> Path:
    return run_dir / f"robot_{robot}_grid"


def gt_trajectory_path(run_dir: Path, robot: int) -> Path:
    return run_dir / f"trajectory_{robot}_gt.tum"


def est_trajectory_path(run_dir: Path, robot: int) -> Path:
    return run_dir / f"trajectory_{robot}_est.tum"


MERGED_MAP = "merged_map.ply"
MERGED_GRID = "grid"
TIMESERIES = "timeseries.csv"
LIVE = "live.json"  # what only the live run can know: wall time, traffic, completion
METRICS = "metrics.json"
FRONTIERS = "frontiers.json"
EVENTS = "events.jsonl"  # goals, goal statuses, navigation states per robot (explain.py)
