"""Realistic (Kinect v2-like) and ideal sensors: invalid returns, presets, seeds, CLI."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest
from typer.testing import CliRunner

from services.config import SpacemapConfig, load_config
from services.simulator.camera import GEOMGROUP, intrinsics
from services.simulator.config import SimConfig
from services.simulator.core import Simulation
from services.simulator.sensor_model import PRESETS, invalid_return_mask, sensor_model

K = intrinsics(160, 120, 68.16)  # mission camera: 84.1° horizontal FoV at 160×120


def rays(K: np.ndarray, shape: tuple[int, int] = (120, 160)) -> np.ndarray:
    """(H, W, 3) optical-frame rays with z = 1."""
    v, u = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    return np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1)


def plane_depth(normal: np.ndarray, dist_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(z-depth, incidence angle in degrees) of the plane n·X = dist_m (n toward −camera)."""
    n = normal / np.linalg.norm(normal)
    r = rays(K)
    nr = r @ n
    with np.errstate(divide="ignore"):
        z = np.where(nr > 1e-9, dist_m / nr, 0.0)
    cos = np.abs(nr) / np.linalg.norm(r, axis=-1)
    return z.astype(np.float32), np.degrees(np.arccos(np.clip(cos, 0, 1)))


# -- the pure mask -----------------------------------------------------------------------------
def test_head_on_plane_keeps_every_pixel() -> None:
    z, _ = plane_depth(np.array([0.0, 0.0, 1.0]), 2.0)
    assert not invalid_return_mask(z, K, 80.0, 0.1).any()


@pytest.mark.parametrize("normal", [(1.0, 0.0, 0.35), (0.0, -1.0, 0.25), (0.7, -0.5, 0.4)])
def test_grazing_pixels_follow_the_true_incidence_angle(normal: tuple[float, ...]) -> None:
    # Tilted walls and a floor-like plane: the mask from finite differences of the depth must
    # agree with the analytic incidence angle of each pixel (0.3° of slack at the threshold).
    z, angle = plane_depth(np.array(normal), 0.6)
    seen = z > 0
    mask = invalid_return_mask(z, K, 80.0, 0.0)
    assert (mask[seen & (angle > 80.3)]).all()
    assert not (mask[seen & (angle < 79.7)]).any()
    assert (seen & (angle > 80.3)).sum() > 200 and (seen & (angle < 79.7)).sum() > 200


def test_depth_edge_invalidates_the_far_side_only() -> None:
    z = np.full((120, 160), 3.0, np.float32)  # wall at 3 m ...
    z[40:80, 60:100] = 2.0  # ... and a box 1 m in front of it
    mask = invalid_return_mask(z, K, 80.0, 0.1)
    ring = np.zeros_like(mask)  # wall pixels with a box pixel among their 4 neighbours
    ring[39:81, 60:100] = ring[40:80, 59:101] = True
    ring[40:80, 60:100] = False
    assert (mask == ring).all()  # those, and nothing else
    assert not invalid_return_mask(z, K, 90.0, 0.0).any()  # both tests off


def test_small_steps_and_missing_returns_are_not_edges() -> None:
    z = np.full((120, 160), 3.0, np.float32)
    z[40:80, 60:100] = 2.85  # 5 % step: a picture frame, not a flying-pixel edge
    z[:10] = 0.0  # no return (sky): the far side of its border, already empty
    mask = invalid_return_mask(z, K, 80.0, 0.1)
    assert not mask.any()


# -- rendered frames ---------------------------------------------------------------------------
@pytest.fixture(scope="module", params=["gl", "raycast"])
def along_wall(request: pytest.FixtureRequest) -> tuple[Simulation, Simulation]:
    # Facing +x 0.2 m from the living room's north wall (inner face y = 4.95): the wall is
    # seen at 80° of incidence 1.13 m ahead and beyond; straight ahead the plant's front face
    # (x = 11.5) is seen head-on 3.85 m away, the east wall behind it.
    cfg = SimConfig(world="house", robots=1, spawn=[(7.6, 4.75, 0.0)],
                    render_backend=request.param)
    pair = Simulation(cfg), Simulation(cfg.model_copy(update={"sensors": "ideal"}))
    yield pair
    for sim in pair:
        sim.close()


def test_rendered_grazing_wall_loses_its_returns(along_wall: tuple[Simulation, Simulation]) -> None:
    real, ideal = along_wall
    img0 = ideal.render(0, segmentation=True)
    d0, seg = img0.depth_m, img0.segmentation
    d = real.render(0).depth_m
    wall = seg == real.model.geom("wall_living_north_1").id
    # Not the 1-px seam with the floor: a normal from finite differences mixes both surfaces.
    wall[1:-1, 1:-1] &= wall[:-2, 1:-1] & wall[2:, 1:-1] & wall[1:-1, :-2] & wall[1:-1, 2:]
    far, near = wall & (d0 > 1.5), wall & (d0 > 0) & (d0 < 0.8)  # > 82.4°, < 76°
    assert far.sum() > 100 and near.sum() > 100
    assert (d[far] == 0).all()
    assert (d[near] > 0).all()


def test_rendered_head_on_surface_keeps_its_returns(
    along_wall: tuple[Simulation, Simulation],
) -> None:
    real, ideal = along_wall
    img0 = ideal.render(0, segmentation=True)
    plant = img0.segmentation == real.model.geom("plant").id
    d = real.render(0).depth_m
    assert plant.sum() > 100
    assert (d[plant] > 0).all()
    sigma = 0.0005 * img0.depth_m[plant] ** 2
    assert (np.abs(d[plant] - img0.depth_m[plant]) < 6 * sigma).all()  # noise, nothing else


def test_rendered_depth_edges_lose_their_far_side(
    along_wall: tuple[Simulation, Simulation],
) -> None:
    real, ideal = along_wall
    d0, d = ideal.render(0).depth_m, real.render(0).depth_m
    pairs = 0
    for axis in (0, 1):  # vertical, then horizontal neighbours
        a, b = np.moveaxis(d0, axis, 0)[:-1], np.moveaxis(d0, axis, 0)[1:]
        da, db = np.moveaxis(d, axis, 0)[:-1], np.moveaxis(d, axis, 0)[1:]
        jump = (a > 0) & (b > 0) & (np.abs(a - b) > 0.2 * np.minimum(a, b))
        assert (da[jump & (a > b)] == 0).all() and (db[jump & (b > a)] == 0).all()
        pairs += jump.sum()
    assert pairs > 20


def test_ideal_depth_is_exact_and_seed_free() -> None:
    cfg = SimConfig(world="house", robots=1, spawn=[(8.0, 3.0, 0.3)], sensors="ideal",
                    render_backend="raycast")
    a, b = Simulation(cfg), Simulation(cfg.model_copy(update={"seed": 5}))
    da = a.render(0).depth_m
    assert np.array_equal(da, b.render(0).depth_m)
    T = a.data.cam_xmat[a.robots[0].camera].reshape(3, 3)  # MuJoCo camera frame in world
    origin = a.data.cam_xpos[a.robots[0].camera].copy()
    r = rays(a.K)
    checked = 0
    for v in range(1, 120, 7):
        for u in range(2, 160, 9):
            ray_mj = np.array([r[v, u, 0], -r[v, u, 1], -1.0])  # optical → MuJoCo camera
            z = mujoco.mj_ray(a.model, a.data, origin, T @ ray_mj, GEOMGROUP, 1,
                              a.robots[0].body, np.zeros(1, np.int32))
            expected = z if 0 < z <= cfg.range_m else 0.0
            assert da[v, u] == pytest.approx(expected, abs=1e-5)
            checked += expected > 0
    assert checked > 150


def test_realistic_frames_and_odometry_are_seeded() -> None:
    def run(seed: int) -> tuple[bytes, tuple]:
        sim = Simulation(SimConfig(world="house", robots=1, seed=seed, render_backend="raycast"))
        for _ in range(30):
            sim.step({0: (0.4, 0.3)})
        return sim.render(0).depth_m.tobytes(), sim.odometry(0).pose

    first, again, other = run(1), run(1), run(2)
    assert first == again
    assert first[0] != other[0] and first[1] != other[1]


def test_realistic_odometry_has_a_random_walk() -> None:
    poses = []
    for sensors in ("realistic", "ideal"):
        cfg = SimConfig(world="bookstore", robots=1, spawn=[(1.0, 1.2, 0.0)], sensors=sensors)
        sim = Simulation(cfg)
        for _ in range(40):
            sim.step({0: (0.5, 0.0)})
        poses.append(np.array(sim.odometry(0).pose))
    assert 1e-4 < np.abs(poses[0] - poses[1])[:2].max() < 0.1


# -- presets, config and CLI -------------------------------------------------------------------
def test_presets_and_explicit_overrides() -> None:
    assert sensor_model(SimConfig()) == PRESETS["realistic"]
    realistic = PRESETS["realistic"]
    assert realistic.depth_noise_per_m2 == 0.0005
    assert realistic.odom_noise_m_per_sqrt_m == realistic.odom_noise_rad_per_sqrt_rad == 0.01
    ideal = sensor_model(SimConfig(sensors="ideal"))
    assert ideal.depth_noise_per_m2 == ideal.odom_noise_m_per_sqrt_m == 0
    assert ideal.odom_noise_rad_per_sqrt_rad == ideal.edge_rel_jump == 0
    assert ideal.max_incidence_deg == 90
    # An explicit field wins over either preset; the rest still follows the preset.
    mixed = sensor_model(SimConfig(sensors="ideal", depth_noise_per_m2=0.001))
    assert mixed.depth_noise_per_m2 == 0.001 and mixed.odom_noise_m_per_sqrt_m == 0
    off = sensor_model(SimConfig(depth_edge_rel_jump=0, odom_noise_m_per_sqrt_m=0))
    assert off.edge_rel_jump == 0 and off.odom_noise_m_per_sqrt_m == 0
    assert off.max_incidence_deg == realistic.max_incidence_deg
    with pytest.raises(ValueError):
        SimConfig(sensors="perfect")


def test_environment_selects_the_preset_and_reaches_the_simulator() -> None:
    cfg = load_config(environ={"SPACEMAP__SIM__SENSORS": "ideal", "SPACEMAP__SIM__ROBOTS": "1"})
    assert cfg.sim.sensors == "ideal"
    sim = Simulation(cfg.sim)
    assert sim.sensors == PRESETS["ideal"] and sim.camera.sensors == PRESETS["ideal"]
    assert sim._odom[0].noise.noise_m_per_sqrt_m == 0
    sim.close()
    assert Simulation(load_config(environ={}).sim).sensors == PRESETS["realistic"]


@pytest.fixture
def missions(monkeypatch: pytest.MonkeyPatch) -> list[SpacemapConfig]:
    """Configs `spacemap run` would start; no mission is ever started."""
    import services.launcher.run as launcher

    seen: list[SpacemapConfig] = []

    def fake_run_mission(cfg: SpacemapConfig, out_dir: Path, **_: object) -> None:
        seen.append(cfg)
        raise launcher.MissionError("stop here")

    monkeypatch.setattr(launcher, "run_mission", fake_run_mission)
    monkeypatch.delenv("SPACEMAP__SIM__SENSORS", raising=False)
    return seen


@pytest.mark.parametrize("flag", [[], ["--sensors", "ideal"], ["--sensors", "realistic"]])
def test_cli_flag_sets_the_preset(
    flag: list[str], missions: list[SpacemapConfig], tmp_path: Path
) -> None:
    from services.cli import app

    result = CliRunner().invoke(app, ["run", "--out", str(tmp_path), *flag])
    assert result.exit_code == 1, result.output
    assert missions[0].sim.sensors == (flag[1] if flag else "realistic")


def test_cli_rejects_an_unknown_preset(missions: list[SpacemapConfig], tmp_path: Path) -> None:
    from services.cli import app

    result = CliRunner().invoke(app, ["run", "--out", str(tmp_path), "--sensors", "perfect"])
    assert result.exit_code == 2 and "sensors" in result.output
    assert not missions
