"""Worlds load with robots, robots spawn in free space, the AWS house uses SPEC §4 spawns."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from services.evaluator.free_space import reachable_free_grid
from services.simulator.config import SimConfig
from services.simulator.core import Simulation, build_model
from services.simulator.worlds import PROXY_GROUP, list_worlds, load_world, spawn_poses
from tests.conftest import AWS_HOUSE

needs_aws = pytest.mark.skipif(not AWS_HOUSE.is_file(), reason=f"{AWS_HOUSE} absent")


def assert_spawned_in_free_space(sim: Simulation) -> None:
    """No contacts at rest, poses as spawned, every robot on the evaluator's reachable floor."""
    assert sim.robot_contacts() == []
    sim.step({})  # at rest nothing pushes them either
    sim.step({})
    assert sim.robot_contacts() == []
    for i, (x, y, yaw) in enumerate(sim.spawns):
        assert np.allclose(sim.true_pose(i), (x, y, yaw), atol=1e-6)
    xy = np.array([(x, y) for x, y, _ in sim.spawns])
    truth = reachable_free_grid(load_world(sim.cfg.world).compile(), xy)
    rc = truth.spec.cell_of(xy)
    assert truth.centres[rc[:, 0], rc[:, 1]].all()


@pytest.mark.parametrize(
    ("world", "robots"),
    [(w, n) for w in list_worlds() for n in (3, 6)] + [("warehouse", 24)],
)
def test_world_loads_with_robots_in_free_space(world: str, robots: int) -> None:
    assert_spawned_in_free_space(Simulation(SimConfig(world=world, robots=robots)))


def test_smoke_drive_every_world() -> None:
    for world in list_worlds():
        sim = Simulation(SimConfig(world=world, robots=3))
        for _ in range(20):
            sim.step({i: (0.4, 0.3 * (i - 1)) for i in range(3)})
        moved = [np.hypot(*np.subtract(sim.true_pose(i)[:2], sim.spawns[i][:2])) for i in range(3)]
        assert min(moved) > 0.5, world


@pytest.mark.parametrize("robots", [1, 3, 6])
def test_world_file_without_spawns_gets_free_poses(tmp_path: Path, robots: int) -> None:
    path = tmp_path / "plain_bookstore.xml"
    path.write_text(load_world("bookstore").to_xml())
    poses = spawn_poses(str(path), robots)
    assert poses == spawn_poses(str(path), robots)  # deterministic
    gaps = [np.hypot(a[0] - b[0], a[1] - b[1]) for a, b in zip(poses, poses[1:], strict=False)]
    assert all(0.55 < g < 1.5 for g in gaps)  # close together, as the paper's teams start
    assert_spawned_in_free_space(Simulation(SimConfig(world=str(path), robots=robots)))


def test_auto_spawns_stay_inside_a_closed_building(tmp_path: Path) -> None:
    # A small closed room inside a large open yard: the yard touches the grid border.
    spec = mujoco.MjSpec()
    spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[20, 20, 0.1])
    for name, pos, size in (
        ("s", (0, -1.5, 1), (2, 0.05, 1)), ("n", (0, 1.5, 1), (2, 0.05, 1)),
        ("w", (-2, 0, 1), (0.05, 1.5, 1)), ("e", (2, 0, 1), (0.05, 1.5, 1)),
        ("far_post", (15, 15, 1), (0.1, 0.1, 1)),
    ):
        spec.worldbody.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX, pos=pos, size=size)
    path = tmp_path / "room.xml"
    path.write_text(spec.to_xml())
    for x, y, _ in spawn_poses(str(path), 3):
        assert -2 < x < 2 and -1.5 < y < 1.5


def test_house_size_and_colours() -> None:
    model = load_world("house").compile()
    walls = [i for i in range(model.ngeom) if model.geom(i).name.startswith("wall_")]
    lo = np.min([model.geom_pos[i] - model.geom_size[i] for i in walls], axis=0)
    hi = np.max([model.geom_pos[i] + model.geom_size[i] for i in walls], axis=0)
    area = (hi[0] - lo[0]) * (hi[1] - lo[1])
    assert 70 <= area <= 150
    assert hi[2] == pytest.approx(2.5)
    boxes = model.geom_type == mujoco.mjtGeom.mjGEOM_BOX
    colours = {tuple(np.round(c, 3)) for c in model.geom_rgba[boxes]}
    assert len(colours) > 0.5 * boxes.sum()  # mostly distinct surface colours


def test_spawn_rows_face_x() -> None:
    poses = spawn_poses("house", 6)
    assert len({(round(x, 3), round(y, 3)) for x, y, _ in poses}) == 6
    assert all(yaw == 0.0 for *_, yaw in poses)
    assert spawn_poses("house", 2, [(1, 2, 0.5), (3, 4, 0.0)]) == [(1, 2, 0.5), (3, 4, 0.0)]
    with pytest.raises(ValueError):
        spawn_poses("/nonexistent/world.xml", 3)
    with pytest.raises(ValueError):
        spawn_poses("house", 3, [(1, 2, 0.5)])  # too few poses


@needs_aws
@pytest.mark.parametrize(
    ("robots", "expected"),
    [
        (3, {(2.9, 1.0), (3.5, 1.0), (4.1, 1.0)}),
        (6, {(x, y) for x in (2.9, 3.5, 4.1) for y in (0.7, 1.3)}),
    ],
)
def test_aws_house_spawns(robots: int, expected: set[tuple[float, float]]) -> None:
    sim = Simulation(SimConfig(world=str(AWS_HOUSE), robots=robots))
    got = {(round(sim.true_pose(i)[0], 3), round(sim.true_pose(i)[1], 3)) for i in range(robots)}
    assert got == expected
    assert all(abs(sim.true_pose(i)[2]) < 1e-9 for i in range(robots))
    sim.step({})
    assert sim.robot_contacts() == []


@needs_aws
def test_aws_proxies_hidden_but_collide() -> None:
    model = build_model(SimConfig(world=str(AWS_HOUSE))).model
    proxies = model.geom_group == PROXY_GROUP
    assert proxies.any()
    assert (model.geom_contype[proxies] > 0).all()
    exact = model.geom_group == 1
    assert exact.any() and (model.geom_contype[exact] == 0).all()
