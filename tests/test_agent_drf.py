"""DRF: projection against the simulator's own camera, removal on synthetic and MuJoCo frames."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.robot_agent.drf import DrfParams, filter_mask, project_target, target_in_base
from services.robot_agent.projection import T_base_cam_forward, intrinsics
from services.robot_agent.synthetic import BoxWorld, T_world_cam_of, render

K = intrinsics(160, 120, math.radians(84.1))
T_BASE_CAM = T_base_cam_forward(0.35, 0.05)
ROOM = BoxWorld.room(-1.0, 6.0, -3.0, 3.0)


def _robot_box(x: float, y: float) -> tuple[float, float, float, float, float, float]:
    return (x - 0.14, x + 0.14, y - 0.153, y + 0.153, 0.02, 0.38)


@pytest.mark.parametrize("error_xy", [(0.0, 0.0), (0.15, -0.1)])
def test_synthetic_teammate_removed_walls_kept(error_xy: tuple[float, float]) -> None:
    obs, mate = (0.0, 0.0, 0.1), (2.5, 0.6)
    T_wc = T_world_cam_of(*obs, T_BASE_CAM)
    depth, _ = render(ROOM.with_box(_robot_box(*mate)), K, (120, 160), T_wc, 5.0)
    empty, _ = render(ROOM, K, (120, 160), T_wc, 5.0)
    teammate = (depth > 0) & (np.abs(depth - empty) > 1e-4)
    assert teammate.sum() > 100
    estimate = np.array([[mate[0] + error_xy[0], mate[1] + error_xy[1]]])
    mask = filter_mask(depth, K, T_BASE_CAM, obs, estimate, DrfParams(c=0.25))
    assert (mask & teammate).sum() >= 0.99 * teammate.sum()
    assert (mask & ~teammate).sum() <= 0.001 * (~teammate).sum()


def test_far_off_estimate_removes_nothing_static() -> None:
    obs, mate = (0.0, 0.0, 0.0), (2.5, 0.6)
    depth, _ = render(ROOM, K, (120, 160), T_world_cam_of(*obs, T_BASE_CAM), 5.0)
    mask = filter_mask(depth, K, T_BASE_CAM, obs, np.array([mate]), DrfParams(c=0.25))
    assert not mask.any()  # only floor and walls around the estimate: no robot-sized cluster


@pytest.fixture(scope="module")
def sim():
    from services.simulator.config import SimConfig
    from services.simulator.core import Simulation

    s = Simulation(SimConfig(world="house", robots=2, spawn=[(6.0, 1.5, 0.0), (8.0, 1.9, 2.0)],
                             render_backend="raycast"))
    yield s
    s.close()


def test_projection_lands_on_the_teammate_in_the_simulator(sim) -> None:
    img = sim.render(0, segmentation=True)
    mate_px = np.isin(img.segmentation, sim.robots[1].geoms)
    assert mate_px.sum() > 50
    obs, mate = sim.true_pose(0), sim.true_pose(1)
    centre = target_in_base(obs, np.array(mate[:2]), float(sim.T_base_cam(0)[2, 3]))
    proj = project_target(centre, sim.K, sim.T_base_cam(0))
    u, v = int(round(proj.u)), int(round(proj.v))
    rows, cols = np.nonzero(mate_px)
    assert cols.min() <= u <= cols.max() and rows.min() <= v <= rows.max() + 1
    assert abs(proj.d - math.hypot(mate[0] - obs[0], mate[1] - obs[1]) + 0.05) < 0.1


def test_drf_on_a_simulated_frame(sim) -> None:
    img = sim.render(0, segmentation=True)
    mate_px = np.isin(img.segmentation, sim.robots[1].geoms) & (img.depth_m > 0)
    static = (img.depth_m > 0) & ~mate_px
    obs, mate = sim.true_pose(0), sim.true_pose(1)
    estimate = np.array([[mate[0] + 0.1, mate[1] - 0.08]])  # estimates are never exact
    mask = filter_mask(img.depth_m, sim.K, sim.T_base_cam(0), obs, estimate, DrfParams(c=0.25))
    assert (mask & mate_px).sum() >= 0.99 * mate_px.sum()
    assert (mask & static).sum() <= 0.01 * static.sum()
