"""Worlds load with robots, robots spawn in free space, the AWS house uses SPEC §4 spawns."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from services.simulator.config import SimConfig
from services.simulator.core import Simulation, build_model
from services.simulator.worlds import PROXY_GROUP, list_worlds, load_world, spawn_poses

SHARED = Path(__file__).resolve().parents[2] / "shared"
AWS_HOUSE = SHARED / "worlds" / "aws_small_house" / "small_house.xml"
needs_aws = pytest.mark.skipif(not AWS_HOUSE.is_file(), reason=f"{AWS_HOUSE} absent")


@pytest.mark.parametrize("world", list_worlds())
@pytest.mark.parametrize("robots", [3, 6])
def test_world_loads_with_robots_in_free_space(world: str, robots: int) -> None:
    sim = Simulation(SimConfig(world=world, robots=robots))
    assert sim.robot_contacts() == []
    sim.step({})  # at rest nothing pushes them either
    sim.step({})
    assert sim.robot_contacts() == []
    for i, (x, y, yaw) in enumerate(sim.spawns):
        assert np.allclose(sim.true_pose(i), (x, y, yaw), atol=1e-6)


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
