"""Ground truth for the world a mission ran in, built from the simulator's own world code."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from services.evaluator.config import EvalConfig
from services.evaluator.ground_truth import GroundTruth, ground_truth
from services.simulator.config import SimConfig
from services.simulator.sensor_model import sensor_model
from services.simulator.worlds import load_world, spawn_poses


def eval_config_for(sim: SimConfig) -> EvalConfig:
    """The evaluator's camera and robot parameters, taken from the simulator's config (its
    sensor preset's incidence limit too: what the camera can never return is not truth)."""
    half_vfov = math.atan(math.tan(math.radians(sim.hfov_deg) / 2.0) * sim.height / sim.width)
    incidence = sensor_model(sim).max_incidence_deg
    return EvalConfig(
        camera_height_m=sim.camera_height_m,
        range_m=sim.range_m,
        max_elevation_deg=math.degrees(half_vfov),
        max_incidence_deg=incidence if 0 < incidence < 90 else None,
    )


def world_ground_truth(sim: SimConfig, cache_dir: Path | None = None) -> GroundTruth:
    """Cached ground truth of `sim.world` (the world alone: robots never block the truth)."""
    model = load_world(sim.world).compile()
    spawns = spawn_poses(sim.world, sim.robots, sim.spawn)
    spawn_xy = np.array([(x, y) for x, y, _ in spawns], dtype=np.float64)
    return ground_truth(model, spawn_xy, eval_config_for(sim), cache_dir)
