"""One typed config for a whole mission: YAML, then environment, then CLI, in that order.

Environment variables look like `SPACEMAP__SIM__ROBOTS=6` (section and field, double
underscores); values are parsed as YAML scalars. CLI overrides are dotted keys
(`{"sim.robots": 6}`). The effective config is written next to each run's outputs.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ConfigDict, Field, model_validator

from services.common.bus import BusConfig
from services.edge_server.config import EdgeConfig
from services.launcher.config import RecordConfig
from services.robot_agent.config import AgentConfig
from services.simulator.config import SimConfig

ENV_PREFIX = "SPACEMAP__"


class SpacemapConfig(BaseModel):
    """The effective configuration of a mission, one section per service."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    bus: BusConfig = Field(default_factory=BusConfig)
    sim: SimConfig = Field(default_factory=SimConfig)
    agent: AgentConfig = Field(default_factory=AgentConfig)
    edge: EdgeConfig = Field(default_factory=EdgeConfig)
    record: RecordConfig = Field(default_factory=RecordConfig)

    @model_validator(mode="before")
    @classmethod
    def _edge_knows_robot_speeds(cls, tree: Any) -> Any:
        """The edge costs goals in the agents' travel time: it copies their speed limits
        unless its section sets them."""
        if not isinstance(tree, Mapping):
            return tree
        agent = tree.get("agent") or {}
        edge = dict(tree.get("edge") or {})
        if not isinstance(agent, Mapping) or not isinstance(tree.get("edge") or {}, Mapping):
            return tree
        for edge_key, agent_key in (("nav_v_mps", "max_v_mps"),
                                    ("nav_omega_radps", "max_omega_radps")):
            if agent_key in agent and edge_key not in edge:
                edge[edge_key] = agent[agent_key]
        sim = tree.get("sim") or {}
        if isinstance(sim, Mapping):
            edge.update({k: v for k, v in _camera_of(sim).items() if k not in edge})
        return {**tree, "edge": edge}


def _camera_of(sim: Mapping[str, Any]) -> dict[str, float]:
    """The edge's camera fields from what the sim section sets (its defaults otherwise)."""
    out: dict[str, float] = {}
    if "camera_height_m" in sim:
        out["camera_height_m"] = sim["camera_height_m"]
    if "range_m" in sim:
        out["camera_range_m"] = sim["range_m"]
    if any(k in sim for k in ("hfov_deg", "width", "height")):
        field = SimConfig.model_fields
        hfov, w, h = (float(sim.get(k, field[k].default)) for k in ("hfov_deg", "width",
                                                                      "height"))
        out["camera_half_vfov_deg"] = math.degrees(math.atan(math.tan(math.radians(hfov) / 2)
                                                             * h / w))
    return out


def _set_dotted(tree: dict[str, Any], dotted: str, value: Any) -> None:
    *parents, leaf = dotted.split(".")
    node = tree
    for part in parents:
        node = node.setdefault(part, {})
        if not isinstance(node, dict):
            raise ValueError(f"{dotted}: {part} is not a section")
    node[leaf] = value


def env_overrides(environ: Mapping[str, str]) -> dict[str, Any]:
    """Dotted overrides from `SPACEMAP__SECTION__FIELD` variables."""
    out: dict[str, Any] = {}
    for name, raw in environ.items():
        if name.startswith(ENV_PREFIX):
            dotted = name[len(ENV_PREFIX) :].lower().replace("__", ".")
            out[dotted] = yaml.safe_load(raw) if raw != "" else ""
    return out


def load_config(
    yaml_path: Path | None = None,
    overrides: Mapping[str, Any] | None = None,
    environ: Mapping[str, str] | None = None,
) -> SpacemapConfig:
    """YAML file, then environment, then `overrides` (dotted keys); validated."""
    tree: dict[str, Any] = {}
    if yaml_path is not None:
        loaded = yaml.safe_load(Path(yaml_path).read_text()) or {}
        if not isinstance(loaded, dict):
            raise ValueError(f"{yaml_path}: top level must be a mapping")
        tree = loaded
    layers = [env_overrides(os.environ if environ is None else environ), dict(overrides or {})]
    for layer in layers:
        for dotted, value in layer.items():
            _set_dotted(tree, dotted, value)
    return SpacemapConfig.model_validate(tree)


def write_config(config: SpacemapConfig, path: Path) -> None:
    """Write the effective config as YAML (loadable by `load_config`)."""
    path.write_text(yaml.safe_dump(config.model_dump(mode="json"), sort_keys=False))
