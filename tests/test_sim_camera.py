"""RGB-D frames agree with MuJoCo ray casts, and K / T_base_cam project world points right."""

from __future__ import annotations

import logging
import math

import mujoco
import numpy as np
import pytest

from services.common.geometry import T_from_xyyaw, invert
from services.simulator import camera as camera_module
from services.simulator.camera import GEOMGROUP
from services.simulator.config import SimConfig
from services.simulator.core import Simulation


@pytest.fixture(scope="module", params=["gl", "raycast"])
def house(request: pytest.FixtureRequest) -> Simulation:
    # Robot 0 faces the TV (south wall) from the middle of the living room. Ideal sensors:
    # these tests are about geometry (depth, K, extrinsics, segmentation); the realistic model
    # is tested in test_sim_sensors.py.
    cfg = SimConfig(
        world="house", robots=2, spawn=[(9.1, 1.5, -math.pi / 2), (8.0, 3.0, 0.3)],
        render_backend=request.param, sensors="ideal",
    )
    sim = Simulation(cfg)
    yield sim
    sim.close()


def T_world_cam(sim: Simulation, i: int) -> np.ndarray:
    return T_from_xyyaw(*sim.true_pose(i)) @ sim.T_base_cam(i)


def ray_depth(sim: Simulation, i: int, u: float, v: float) -> float:
    """z-depth of pixel (u, v) by mj_ray, 0 when nothing within range."""
    T = T_world_cam(sim, i)
    ray_cam = np.array([(u - sim.K[0, 2]) / sim.K[0, 0], (v - sim.K[1, 2]) / sim.K[1, 1], 1.0])
    dist = mujoco.mj_ray(
        sim.model, sim.data, T[:3, 3], T[:3, :3] @ ray_cam, GEOMGROUP, 1,
        sim.robots[i].body, np.zeros(1, np.int32),
    )
    return dist if 0 < dist <= sim.cfg.range_m else 0.0


@pytest.mark.parametrize("robot", [0, 1])
def test_depth_matches_ray_casts(house: Simulation, robot: int) -> None:
    img = house.render(robot)
    h, w = img.depth_m.shape
    assert img.rgb.shape == (h, w, 3) and img.rgb.dtype == np.uint8
    assert img.depth_m.dtype == np.float32
    errors = []
    for v in range(3, h, 9):
        for u in range(2, w, 11):
            errors.append(abs(float(img.depth_m[v, u]) - ray_depth(house, robot, u, v)))
    errors = np.array(errors)
    assert np.median(errors) < 0.005
    assert np.mean(errors < 0.02) > 0.95
    assert (img.depth_m > 0).mean() > 0.3


def test_known_point_projects_where_rendered(house: Simulation) -> None:
    tv = house.model.geom("tv").id
    x, y, z = house.model.geom_pos[tv]
    p_world = np.array([x, y + house.model.geom_size[tv][1], 0.8, 1.0])  # TV front face
    p_cam = invert(T_world_cam(house, 0)) @ p_world
    uvw = house.K @ p_cam[:3]
    u, v = (int(round(c)) for c in uvw[:2] / uvw[2])
    img = house.render(0, segmentation=True)
    assert 0 <= u < house.cfg.width and 0 <= v < house.cfg.height
    assert img.depth_m[v, u] == pytest.approx(p_cam[2], abs=0.01)
    assert img.segmentation[v, u] == tv


def test_camera_never_sees_its_own_robot(house: Simulation) -> None:
    img = house.render(1, segmentation=True)
    seg = img.segmentation
    assert seg.shape == img.depth_m.shape and seg.dtype == np.int32
    own = set(house.robots[1].geoms)
    assert not own & set(np.unique(seg).tolist())  # never sees itself


def test_depth_noise_is_seeded_and_grows_with_depth() -> None:
    cfg = SimConfig(world="house", robots=1, depth_noise_per_m2=0.01, render_backend="raycast")
    a, b = Simulation(cfg), Simulation(cfg)
    clean = Simulation(cfg.model_copy(update={"sensors": "ideal", "depth_noise_per_m2": None}))
    da, db, d0 = a.render(0).depth_m, b.render(0).depth_m, clean.render(0).depth_m
    assert np.array_equal(da, db)
    both = (da > 0) & (d0 > 0)
    err = (da - d0)[both] / d0[both] ** 2
    assert 0.005 < err.std() < 0.02


def test_depth_noise_adds_no_returns_from_the_sky() -> None:
    # GL's background depth is the far plane (~1 km); noise ∝ depth² must not pull any of it
    # into range (3 % of such pixels did: mid-air ghosts in missions)
    cfg = SimConfig(world="house", robots=1, depth_noise_per_m2=0.0005, seed=3)
    noisy, clean = Simulation(cfg), Simulation(cfg.model_copy(update={"depth_noise_per_m2": 0}))
    # (both keep the realistic invalid returns, which are deterministic)
    d0 = clean.render(0).depth_m
    assert (d0 == 0).sum() > 1000  # the spawn view has sky above the walls
    for _ in range(3):  # three noise draws
        dn = noisy.render(0).depth_m
        new = (dn > 0) & (d0 == 0)
        assert (dn[new] > cfg.range_m - 0.1).all()  # only surfaces just past the range
    noisy.close()
    clean.close()


def test_segmentation_labels_a_teammate_ahead() -> None:
    # Ideal: about labels and where the teammate is, not about its dropped grazing pixels.
    cfg = SimConfig(world="house", robots=2, spawn=[(6.0, 1.5, 0.0), (7.5, 1.5, 0.0)],
                    sensors="ideal")
    sim = Simulation(cfg)
    img = sim.render(0, segmentation=True)
    teammate = np.isin(img.segmentation, sim.robots[1].geoms)
    assert teammate.sum() > 50
    assert (img.depth_m[teammate] > 1.0).all() and (img.depth_m[teammate] < 1.7).all()
    sim.close()


@pytest.mark.parametrize("backend", ["gl", "raycast"])
def test_hidden_robots_leave_the_wall_behind_them(backend: str) -> None:
    # The ablation `robots_visible=False`: where the teammate stood, the camera sees past it.
    cfg = SimConfig(world="house", robots=2, spawn=[(6.0, 1.5, 0.0), (7.5, 1.5, 0.0)],
                    sensors="ideal", render_backend=backend)
    seen_sim = Simulation(cfg)
    hidden_sim = Simulation(cfg.model_copy(update={"robots_visible": False}))
    seen, hidden = seen_sim.render(0, segmentation=True), hidden_sim.render(0, segmentation=True)
    robot_geoms = [g for r in seen_sim.robots for g in r.geoms]
    teammate = np.isin(seen.segmentation, seen_sim.robots[1].geoms)
    assert teammate.sum() > 50
    assert not np.isin(hidden.segmentation, robot_geoms).any()
    front, behind = seen.depth_m[teammate], hidden.depth_m[teammate]
    returns = behind > 0  # floor and wall behind the teammate, or nothing within range
    assert (behind[returns] > front[returns]).all()
    assert np.median(behind[returns] - front[returns]) > 0.3
    seen_sim.close()
    hidden_sim.close()


def test_auto_backend_falls_back_to_ray_casting_and_logs_it(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    def no_gl(width: int, height: int) -> object:
        raise RuntimeError("no display, no EGL device")

    monkeypatch.setattr(camera_module, "_make_gl_context", no_gl)
    cfg = SimConfig(world="house", robots=1, render_backend="auto")
    sim = Simulation(cfg)
    with caplog.at_level(logging.INFO, logger=camera_module.__name__):
        img = sim.render(0)
    assert sim.camera.backend == "raycast"
    assert any("falls back to mj_multiRay" in r.getMessage() for r in caplog.records)
    assert any("camera backend raycast" in r.getMessage() for r in caplog.records)
    assert (img.depth_m > 0).mean() > 0.3
    with pytest.raises(RuntimeError, match="no EGL device"):
        Simulation(cfg.model_copy(update={"render_backend": "gl"})).render(0)


def test_every_frame_carries_intrinsics_and_extrinsics() -> None:
    cfg = SimConfig(world="house", robots=2, width=320, height=240)
    sim = Simulation(cfg)
    K = sim.K
    # 84.1° horizontal FoV: the image half-width subtends half the FoV at the focal length.
    assert math.degrees(2 * math.atan((cfg.width / 2) / K[0, 0])) == pytest.approx(84.1)
    assert K[0, 0] == pytest.approx(K[1, 1])
    T = sim.T_base_cam(1)
    assert T[:3, 3] == pytest.approx([0.05, 0.0, cfg.camera_height_m])
    assert T[:3, 2] == pytest.approx([1.0, 0.0, 0.0])  # optical axis = base +x
    assert T[:3, 1] == pytest.approx([0.0, 0.0, -1.0])  # image down = base −z
    assert sim.render(1).depth_m.shape == (240, 320)


INFINITE_FLOOR = """<mujoco>
  <worldbody>
    <light pos="0 0 5" dir="0 0 -1"/>
    <geom name="floor" type="plane" size="0 0 0.05" pos="3 -2 0"/>
    <geom name="wall" type="box" size="0.1 3 1" pos="5 0 1"/>
  </worldbody>
</mujoco>
"""


def test_an_infinite_floor_renders_where_rays_hit_it_and_stays_infinite(tmp_path) -> None:
    # The GL context draws an infinite plane finite (the fine far-clip grid cost 2 ms a frame
    # in the AWS house); within range the floor must be where mj_ray finds it, everywhere
    # the robot can stand, and physics and rays keep the infinite plane.
    world = tmp_path / "floor.xml"
    world.write_text(INFINITE_FLOOR)
    for spawn in [(0.0, 0.0, 0.3), (-20.0, 15.0, -2.5), (4.0, -2.5, 0.0)]:
        sim = Simulation(SimConfig(world=str(world), robots=1, spawn=[spawn], sensors="ideal",
                                   render_backend="gl"))
        floor = sim.model.geom("floor").id
        img = sim.render(0, segmentation=True)
        assert sim.model.geom_size[floor, 0] == 0 and sim.model.geom_size[floor, 1] == 0
        on_floor = img.segmentation == floor
        assert on_floor.sum() > 0.2 * on_floor.size
        errors = [abs(float(img.depth_m[v, u]) - ray_depth(sim, 0, u, v))
                  for v, u in np.argwhere(on_floor)[::37]]
        assert np.max(errors) < 0.01
        sim.close()
