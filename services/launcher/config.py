"""Recorder section of the mission config: what the launcher's recordings (mission.rrd,
mission.mcap) and live view keep. Readers only: none of it changes the mission."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


class RecordConfig(BaseModel):
    """mission.rrd (rerun) and mission.mcap (ROS 2) of every run folder."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    rrd: bool = Field(default=True, description="write mission.rrd (rerun recording)")
    mcap: bool = Field(default=True, description="write mission.mcap (ROS 2 CDR messages)")
    cloud_every_s: float = Field(
        default=30.0, ge=0,
        description="sim s between merged clouds kept (taken from the coverage samples, so "
        "never more often than --sample-every); the final map is always kept")
    grid_every_s: float = Field(default=5.0, ge=0, description="sim s between 2D grids kept")
    trajectory_every_s: float = Field(
        default=2.0, gt=0, description="sim s between the rerun trajectory line strips")
    cloud_colors: Literal["robot", "height", "rgb"] = Field(
        default="robot", description="rerun cloud colour: first observer, height or camera")
    camera_every_s: float = Field(
        default=2.0, gt=0, description="sim s between camera images (live view only)")


DEFAULT_VIEW_PORT = 9876


def parse_view(view: str) -> tuple[Literal["spawn", "serve", "url"], int | str]:
    """A live view's target: "spawn[:PORT]" (start a native viewer and stream to it),
    "serve[:PORT]" (host a gRPC server: `rerun rerun+http://HOST:PORT/proxy` connects) or a
    `rerun+http://…/proxy` URL of a viewer already running; ValueError otherwise."""
    if view.startswith(("rerun://", "rerun+http://", "rerun+https://")):
        return "url", view
    mode, _, port_text = view.partition(":")
    if mode in ("spawn", "serve") and (port_text == "" or port_text.isdigit()):
        port = int(port_text) if port_text else DEFAULT_VIEW_PORT
        if 0 < port < 65536:
            return ("spawn" if mode == "spawn" else "serve"), port
    raise ValueError(f"a live view is spawn[:PORT], serve[:PORT] or a rerun+http:// URL, "
                     f"not {view!r}")
