"""A lockstep mission with logins, access control and mutual TLS (router, simulator, edge,
two agents as OS processes) while a client holding agent 0's login misbehaves: it tries to
drive robot 1 and to speak for the edge and the simulator (the router refuses), and it floods
every key agent 0 may publish with bad payloads (every process drops, logs and counts each
one). A client with no login gets no session. The mission runs on and no process dies."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import zenoh

from schemas import DecodeError, decode
from services.common.access import identity, make_credentials
from services.common.bus import connect, open_session
from services.config import load_config, write_config
from services.launcher.monitor import Monitor
from services.launcher.run import start_services
from services.processes import ProcessGroup, free_tcp_port, spacemap_command
from tests.conftest import processes_tagged
from tests.fuzz import bad_payloads, templates
from tests.test_mission_multiprocess import wait_for

pytestmark = pytest.mark.multiprocess

BLOCK = zenoh.CongestionControl.BLOCK
ROUNDS = 4  # bursts, each some ticks after the last


def drop_totals(log: Path) -> dict[str, int]:
    found = re.findall(r"dropped \d+ bad messages in all: (\{.*\})", log.read_text())
    return json.loads(found[-1]) if found else {}


def reasons(topic: str) -> set[str]:
    out = set()
    for _, payload in bad_payloads(templates(0)[topic]):
        try:
            decode(payload, type(templates(0)[topic]))
        except DecodeError as exc:
            out.add(exc.reason)
    return out


def test_logins_rules_and_fuzz_during_a_mission(tmp_path: Path) -> None:
    endpoint = f"tls/127.0.0.1:{free_tcp_port()}"  # mutual TLS, as `spacemap run` does
    cred = tmp_path / "cred"
    make_credentials(cred, robots=2)
    config = load_config(overrides={
        "bus.connect": endpoint, "bus.credentials": str(cred), "sim.robots": 2,
        "sim.max_sim_time_s": 30.0, "sim.seed": 3,
    })
    write_config(config, tmp_path / "config.yaml")
    group = ProcessGroup(tmp_path / "logs")
    group.start("router", spacemap_command(
        "router", "--listen", endpoint, "--config", str(tmp_path / "config.yaml")))
    bursts = {topic: bad_payloads(t, seed=i) for i, (topic, t) in enumerate(templates(0).items())}
    keys = None
    try:
        with connect(config.bus, identity("monitor")) as bus:
            keys = bus.keys
            monitor = Monitor(bus, robots=2)
            start_services(group, tmp_path / "config.yaml", robots=2)
            wait_for(lambda: monitor.clock is not None, monitor, group, 120, "the first tick")
            anonymous = config.bus.model_copy(update={
                "credentials": None, "connect_timeout_s": 2.0, "tls": False,
                "connect": endpoint.replace("tls/", "tcp/")})
            with pytest.raises(zenoh.ZError), open_session(anonymous):
                pass
            with open_session(config.bus, identity("agent", 0)) as rogue:
                forbidden = [keys.cmd_vel(1), keys.goal(1), keys.submap(1), keys.map_grid(),
                             keys.edge_ack(), keys.clock()]
                for n in range(ROUNDS):
                    tick = monitor.clock.tick
                    wait_for(lambda t=tick: monitor.clock.tick >= t + 10, monitor, group, 120,
                             f"10 ticks before burst {n}")
                    for key in forbidden:
                        rogue.put(key, b"forbidden", congestion_control=BLOCK)
                    for topic, payloads in bursts.items():
                        for _, payload in payloads:
                            rogue.put(f"{keys.prefix}/robot/0/{topic}", payload,
                                      congestion_control=BLOCK)
            wait_for(lambda: monitor.sim_time_s >= 25.0, monitor, group, 300, "25 s of sim time")
            for robot, track in monitor.tracks.items():
                xy = np.asarray(track.gt_xyyaw)[:, :2]
                travelled = np.linalg.norm(np.diff(xy, axis=0), axis=1).sum()
                assert travelled > 0.5, f"robot {robot} moved only {travelled:.2f} m"
            monitor.pump(timeout=0.5)
            monitor_drops = bus.dropped.total()
    finally:
        codes = group.stop(order=["sim", "edge", "agent0", "agent1", "router"])
    assert all(code == 0 for code in codes.values()), f"unclean exits: {codes}"
    assert processes_tagged(tmp_path / "logs") == [], "processes left behind"

    n = {topic: len(p) * ROUNDS for topic, p in bursts.items()}
    logs = tmp_path / "logs"
    # every bad payload on a key a process reads is dropped and counted, and nothing forbidden
    # arrives: robot 1's cmd_vel, goal and submap, map/grid, edge/ack and sim/clock would add
    expected = {"sim": n["cmd_vel"], "edge": n["pose"] + n["submap"] + n["goal_status"],
                "agent0": n["pose"], "agent1": n["pose"]}
    for name, count in expected.items():
        assert sum(drop_totals(logs / f"{name}.log").values()) == count, name
    assert monitor_drops == n["pose"] + n["goal_status"]
    sim_log = (logs / "sim.log").read_text()
    assert "robot/1/cmd_vel" not in sim_log
    for reason in reasons("cmd_vel"):  # logged once per (key, reason)
        assert f"dropped message on {keys.cmd_vel(0)}: {reason}" in sim_log, reason
    edge_log = (logs / "edge.log").read_text()
    for reason in reasons("submap"):
        assert f"dropped message on {keys.submap(0)}: {reason}" in edge_log, reason
