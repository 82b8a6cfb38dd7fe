"""Worlds: a registry of procedural worlds built with MjSpec, plus any MJCF file.

Geom groups after `load_world` (one convention for the simulator, its sensors and the
evaluator):
- 0: collide and sensed (walls, furniture, floor plane);
- 1: sensed only, no contacts (exact meshes of converted worlds);
- 2: robots (collide and sensed), added by `robots.add_robots`;
- 3: collide only, hidden from cameras and rays: collision proxies of a file world that also
  has group-1 geometry (otherwise the camera would see the coarse boxes over the real meshes).

Spawns: robots start in rows of three 0.6 m apart facing +x (the paper's setting); the
default poses of a world come from `spawn_poses`; a world file without known spawns gets a
formation placed in its free space automatically (`spawning.auto_spawns`).
"""

from __future__ import annotations

import colorsys
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

WALL_HEIGHT_M = 2.5
WALL_THICKNESS_M = 0.1
TABLE_TOP_M = 0.04
TABLE_LEG_M = 0.05
SENSED_GROUPS = (0, 1, 2)
PROXY_GROUP = 3
ROBOT_GROUP = 2

Pose = tuple[float, float, float]  # (x m, y m, yaw rad) in the world frame


@dataclass(frozen=True)
class SpawnGrid:
    """Rows of `cols` robots `spacing` apart along +x from `x0`, rows centred on `y_centre`."""

    x0: float
    y_centre: float
    yaw: float = 0.0
    cols: int = 3
    spacing: float = 0.6

    def poses(self, n: int) -> list[Pose]:
        rows = math.ceil(n / self.cols)
        return [
            (
                self.x0 + (i % self.cols) * self.spacing,
                self.y_centre + (i // self.cols - (rows - 1) / 2) * self.spacing,
                self.yaw,
            )
            for i in range(n)
        ]


@dataclass(frozen=True)
class WorldSpec:
    """A registered world: how to build it and where robots start."""

    name: str
    build: Callable[[], mujoco.MjSpec]
    spawn: SpawnGrid
    description: str = ""


# Spawns of known MJCF files, matched by the end of their path: the one place that knows them.
FILE_WORLD_SPAWNS: dict[str, SpawnGrid] = {
    "aws_small_house/small_house.xml": SpawnGrid(x0=2.9, y_centre=1.0),  # SPEC §4
}


# -- building blocks ------------------------------------------------------------------------
@dataclass
class _Builder:
    """Adds boxes to a spec with a distinct colour per surface."""

    spec: mujoco.MjSpec = field(default_factory=mujoco.MjSpec)
    count: int = 0

    def colour(self) -> list[float]:
        # Golden-ratio hue steps: neighbouring surfaces get clearly different colours.
        hue = (self.count * 0.618034) % 1.0
        sat = 0.35 + 0.3 * ((self.count * 7) % 3) / 2
        r, g, b = colorsys.hsv_to_rgb(hue, sat, 0.85)
        self.count += 1
        return [r, g, b, 1.0]

    def box(self, name: str, lo: Sequence[float], hi: Sequence[float]) -> None:
        """Axis-aligned box between corners `lo` and `hi` (world frame, metres)."""
        lo_a, hi_a = np.asarray(lo, float), np.asarray(hi, float)
        self.spec.worldbody.add_geom(
            name=name,
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=((hi_a - lo_a) / 2).tolist(),
            pos=((hi_a + lo_a) / 2).tolist(),
            rgba=self.colour(),
            group=0,
        )

    def wall(
        self,
        name: str,
        start: tuple[float, float],
        end: tuple[float, float],
        doors: Sequence[tuple[float, float]] = (),
    ) -> None:
        """Axis-aligned wall from `start` to `end`, open over each (from, to) span in `doors`."""
        horizontal = start[1] == end[1]
        a0, a1 = (start[0], end[0]) if horizontal else (start[1], end[1])
        c = start[1] if horizontal else start[0]
        h = WALL_THICKNESS_M / 2
        cuts = [a0 - h, *[v for d in sorted(doors) for v in d], a1 + h]
        for k in range(0, len(cuts), 2):
            s0, s1 = cuts[k], cuts[k + 1]
            if s1 - s0 < 1e-6:
                continue
            if horizontal:
                self.box(f"{name}_{k // 2}", (s0, c - h, 0), (s1, c + h, WALL_HEIGHT_M))
            else:
                self.box(f"{name}_{k // 2}", (c - h, s0, 0), (c + h, s1, WALL_HEIGHT_M))

    def table(self, name: str, x: float, y: float, sx: float, sy: float, height: float) -> None:
        """Table centred at (x, y): a top and four legs, so robots see under it."""
        self.box(f"{name}_top", (x - sx / 2, y - sy / 2, height - TABLE_TOP_M),
                 (x + sx / 2, y + sy / 2, height))
        leg = TABLE_LEG_M
        for k, (fx, fy) in enumerate(((-1, -1), (-1, 1), (1, -1), (1, 1))):
            lx = x + fx * (sx / 2 - leg / 2)
            ly = y + fy * (sy / 2 - leg / 2)
            self.box(f"{name}_leg{k}", (lx - leg / 2, ly - leg / 2, 0),
                     (lx + leg / 2, ly + leg / 2, height - TABLE_TOP_M))

    def shell(self, width: float, depth: float) -> None:
        """Floor plane, light and outer walls of a width × depth rectangle at the origin."""
        self.spec.modelname = "spacemap_world"
        self.spec.option.timestep = 0.002
        self.spec.worldbody.add_light(
            name="sun", pos=[width / 2, depth / 2, 10], dir=[0.3, 0.2, -1],
            type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL, castshadow=False,
            diffuse=[0.6, 0.6, 0.6], ambient=[0.35, 0.35, 0.35],
        )
        self.spec.worldbody.add_geom(
            name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE,
            size=[width / 2 + 1, depth / 2 + 1, 0.1], pos=[width / 2, depth / 2, 0],
            rgba=[0.55, 0.5, 0.45, 1], group=0,
        )
        self.wall("wall_south", (0, 0), (width, 0))
        self.wall("wall_north", (0, depth), (width, depth))
        self.wall("wall_west", (0, 0), (0, depth))
        self.wall("wall_east", (width, 0), (width, depth))


# -- the built-in worlds --------------------------------------------------------------------
def build_house() -> mujoco.MjSpec:
    """12 × 9 m house (~100 m² free): living room, kitchen, bedroom, study, storage."""
    b = _Builder()
    b.shell(12.0, 9.0)
    b.wall("wall_mid", (5, 0), (5, 9), doors=[(1.6, 2.8), (6.0, 7.2)])
    b.wall("wall_kitchen_bed", (0, 4.5), (5, 4.5), doors=[(1.5, 2.7)])
    b.wall("wall_living_north", (5, 5), (12, 5), doors=[(6.2, 7.4)])
    b.wall("wall_study_store", (9, 5), (9, 9), doors=[(6.4, 7.6)])
    # Living room (x 5-12, y 0-5); robots spawn at its south-west corner.
    b.box("sofa_seat", (10.6, 1.0, 0), (11.9, 3.4, 0.45))
    b.box("sofa_back", (11.6, 1.0, 0.45), (11.9, 3.4, 0.85))
    b.table("coffee_table", 9.2, 2.2, 1.1, 0.6, 0.45)
    b.box("tv_cabinet", (8.0, 0.05, 0), (10.2, 0.45, 0.5))
    b.box("tv", (8.6, 0.15, 0.5), (9.6, 0.25, 1.1))
    b.box("living_shelf", (5.05, 3.4, 0), (5.45, 4.9, 1.8))
    b.box("plant", (11.5, 4.4, 0), (11.9, 4.9, 1.2))
    # Kitchen (x 0-5, y 0-4.5).
    b.box("counter", (0.05, 0.05, 0), (3.8, 0.65, 0.9))
    b.box("fridge", (0.05, 3.6, 0), (0.75, 4.4, 1.8))
    b.table("kitchen_table", 2.4, 2.5, 1.4, 0.9, 0.75)
    b.box("kitchen_stool", (3.6, 2.3, 0), (3.95, 2.65, 0.6))
    # Bedroom (x 0-5, y 4.5-9).
    b.box("bed", (0.05, 6.8, 0), (2.1, 8.4, 0.5))
    b.box("bed_head", (0.05, 6.8, 0.5), (0.2, 8.4, 1.0))
    b.box("nightstand", (0.05, 8.45, 0), (0.5, 8.95, 0.55))
    b.box("wardrobe", (4.3, 7.6, 0), (4.95, 8.95, 2.0))
    b.box("dresser", (3.0, 4.55, 0), (4.4, 5.0, 0.8))
    # Study (x 5-9, y 5-9).
    b.table("desk", 7.0, 8.5, 1.4, 0.7, 0.75)
    b.box("desk_chair", (6.8, 7.55, 0), (7.25, 8.0, 0.5))
    b.box("bookshelf", (5.05, 7.5, 0), (5.45, 8.95, 1.9))
    b.box("filing_cabinet", (8.4, 5.05, 0), (8.95, 5.6, 1.1))
    # Storage (x 9-12, y 5-9).
    b.box("storage_rack", (11.4, 5.3, 0), (11.95, 8.7, 1.6))
    b.box("washer", (9.05, 8.3, 0), (9.7, 8.95, 0.85))
    b.box("crate", (10.0, 5.4, 0), (10.6, 6.0, 0.4))
    return b.spec


def build_bookstore() -> mujoco.MjSpec:
    """10 × 10 m single room with rows of shelves and a sales counter."""
    b = _Builder()
    b.shell(10.0, 10.0)
    for k, y in enumerate((2.6, 4.4, 6.2, 8.0)):
        b.box(f"shelf_row{k}", (2.5, y - 0.2, 0), (8.0, y + 0.2, 2.0))
    b.box("shelf_wall_east", (9.5, 2.0, 0), (9.95, 9.5, 2.2))
    b.box("counter", (7.0, 0.3, 0), (9.0, 0.9, 1.0))
    b.table("reading_table", 1.0, 6.0, 0.9, 1.6, 0.75)
    return b.spec


def build_warehouse() -> mujoco.MjSpec:
    """40 × 30 m hall (1200 m²): racks in aisles with a cross aisle, pallets, a dock area."""
    b = _Builder()
    b.shell(40.0, 30.0)
    for k, y in enumerate(np.arange(7.0, 28.0, 3.5)):
        b.box(f"rack{k}_w", (6.0, y - 0.5, 0), (18.5, y + 0.5, 2.4))
        b.box(f"rack{k}_e", (21.5, y - 0.5, 0), (36.0, y + 0.5, 2.4))
    for k, x in enumerate((10.0, 16.0, 25.0, 31.0)):
        b.box(f"pallet{k}", (x, 2.0, 0), (x + 1.2, 3.0, 1.0))
    b.table("packing_table", 38.0, 4.0, 1.6, 3.0, 0.9)
    return b.spec


WORLDS: dict[str, WorldSpec] = {
    w.name: w
    for w in (
        WorldSpec("house", build_house, SpawnGrid(x0=5.8, y_centre=1.6),
                  "12 × 9 m house, five rooms, furniture"),
        WorldSpec("bookstore", build_bookstore, SpawnGrid(x0=1.0, y_centre=1.2),
                  "10 × 10 m room with shelf rows"),
        WorldSpec("warehouse", build_warehouse, SpawnGrid(x0=2.0, y_centre=3.0),
                  "40 × 30 m warehouse with rack aisles"),
    )
}


def list_worlds() -> list[str]:
    return sorted(WORLDS)


def _file_spawn(path: Path) -> SpawnGrid | None:
    posix = path.resolve().as_posix()
    return next((g for suffix, g in FILE_WORLD_SPAWNS.items() if posix.endswith(suffix)), None)


def load_world(name_or_path: str) -> mujoco.MjSpec:
    """The world alone (no robots) as an MjSpec: a registered name or an MJCF file path."""
    if name_or_path in WORLDS:
        return WORLDS[name_or_path].build()
    path = Path(name_or_path)
    if not path.is_file():
        raise ValueError(f"unknown world {name_or_path!r}: not in {list_worlds()} nor a file")
    spec = mujoco.MjSpec.from_file(str(path.resolve()))  # meshes resolve next to the file
    _hide_proxies(spec)
    return spec


def _hide_proxies(spec: mujoco.MjSpec) -> None:
    """Move group-0 collision proxies to PROXY_GROUP when the world has exact group-1 geoms."""
    geoms = spec.geoms
    if not any(g.group == 1 for g in geoms):
        return
    for g in geoms:
        if g.group == 0 and g.type != mujoco.mjtGeom.mjGEOM_PLANE:
            g.group = PROXY_GROUP


def spawn_poses(
    name_or_path: str, n: int, override: Sequence[Sequence[float]] | None = None
) -> list[Pose]:
    """Spawn poses of `n` robots: `override` (config `sim.spawn`), the world's defaults, or for
    a world file without defaults a formation found in its free space (`spawning`)."""
    if override is not None:
        if len(override) < n:
            raise ValueError(f"sim.spawn has {len(override)} poses for {n} robots")
        return [(float(p[0]), float(p[1]), float(p[2])) for p in override[:n]]
    grid = WORLDS[name_or_path].spawn if name_or_path in WORLDS else _file_spawn(
        Path(name_or_path)
    )
    if grid is None:
        from services.simulator.spawning import auto_spawns  # imports this module

        return auto_spawns(load_world(name_or_path).compile(), n)
    return grid.poses(n)
