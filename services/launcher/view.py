"""`spacemap view`: watch a mission started elsewhere (other hosts, docker compose) in rerun.

A second reader on the bus beside the recorder: it logs in as `monitor` but holds no
liveliness token, subscribes to what the run folder's recorder reads plus the cameras, asks
the edge for the merged cloud every few sim seconds, and publishes nothing.
"""

from __future__ import annotations

import logging
import uuid
from pathlib import Path

from rich.console import Console

from services.common.access import identity
from services.common.bus import connect
from services.common.signals import stop_on_signals
from services.config import SpacemapConfig
from services.evaluator.evaluate import probe_for
from services.launcher.monitor import Monitor
from services.launcher.recorders import Recorders, camera_ticks
from services.launcher.rerun_recorder import RerunRecorder
from services.launcher.run import _watch
from services.launcher.sampler import CoverageSampler

log = logging.getLogger(__name__)


def watch_mission(config: SpacemapConfig, view: str, save: Path | None = None,
                  sample_every_s: float = 5.0, stall_timeout_s: float = 600.0,
                  console: Console | None = None) -> bool:
    """Stream the mission on `config.bus` to the live view `view` (and `save`, an .rrd) until
    it completes (True), reaches its sim-time cap (False) or gets SIGINT/SIGTERM (False)."""
    probe = probe_for(config.sim)
    robots, tick_s = config.sim.robots, config.sim.tick_s
    with connect(config.bus, identity("monitor")) as bus:
        monitor = Monitor(bus, robots, camera_every_ticks=camera_ticks(config), declare=False)
        sampler = CoverageSampler(monitor, probe, sample_every_s, tick_s)
        recorders = Recorders([RerunRecorder(save, robots, config.record, tick_s, view,
                                             str(uuid.uuid4()), monitor.tracks)])
        monitor.sinks.append(recorders)
        sampler.sinks.append(recorders)
        sampler.start()
        try:
            return _watch(monitor, sampler, None, config, stall_timeout_s, console,
                          stop_on_signals())
        finally:
            sampler.stop()
            recorders.close()
