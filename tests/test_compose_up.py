"""`docker compose up` runs the real mission (issue 15).

Makes sure a Docker engine runs (scripts/docker-engine.sh installs Debian's docker.io and
docker-compose and starts dockerd when missing) and builds the image with no registry and no
network in the build (scripts/docker-build.sh), both in the background from the start of the
session (tests/docker_build.py); then starts docker-compose.yml's router, simulator,
edge, three agent replicas and recorder with a short sim-time cap, waits for the recorder's run
folder in the `runs` volume, copies it out, checks metrics.json, and tears everything down.
It never skips: without an engine it fails, saying why (the engine script's log).
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from services.evaluator.metrics import METRICS_KEYS
from tests import docker_build
from tests.conftest import REPO

pytestmark = [pytest.mark.docker, pytest.mark.timeout(1800)]

SIM_TIME_S = 30  # the mission's sim-time cap (SPACEMAP_SIM_TIME)
ROBOTS = 3
COVERAGE_3D_FLOOR = 30.0  # % of the house's surface; 30 s with 3 robots gave 71.8 %
BUILD_TIMEOUT_S = 900  # a cold build: debootstrap + wheelhouse + docker build
MISSION_DEADLINE_S = 600  # `up` to the run folder: 5 min measured on two overloaded cores
RUN = "smoke"


def sh(*argv: str, timeout: float = 120, env: dict[str, str] | None = None,
       check: bool = True) -> subprocess.CompletedProcess[str]:
    proc = subprocess.run(list(argv), cwd=REPO, capture_output=True, text=True,
                          timeout=timeout, env=env)
    if check:
        assert proc.returncode == 0, (f"{' '.join(argv)} failed ({proc.returncode}):\n"
                                      f"{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return proc


def compose_argv() -> list[str]:
    """The compose implementation here: Debian's docker-compose (1.29), else `docker compose`."""
    if shutil.which("docker-compose"):
        return ["docker-compose"]
    return ["docker", "compose"]


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def wait_for(condition: Callable[[], bool], timeout_s: float, what: str,
             poll_s: float = 2.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, f"timed out after {timeout_s:.0f} s: {what}"
        time.sleep(poll_s)


class Project:
    """One compose project (its own name, so it never touches a user's `spacemap` project)."""

    def __init__(self, env: dict[str, str]) -> None:
        self.name = f"spacemapsmoke{os.getpid()}"
        self.env = env
        self.argv = [*compose_argv(), "-p", self.name, "-f", str(REPO / "docker-compose.yml")]

    def __call__(self, *args: str, timeout: float = 180,
                 check: bool = True) -> subprocess.CompletedProcess[str]:
        return sh(*self.argv, *args, timeout=timeout, env=self.env, check=check)

    def containers(self, service: str | None = None) -> list[str]:
        args = ["ps", "-a", "-q"] + ([service] if service else [])
        return self(*args).stdout.split()

    @staticmethod
    def states(ids: list[str]) -> dict[str, tuple[str, int]]:
        """Container name → (status, exit code), by `docker inspect` (cheap to poll)."""
        out = sh("docker", "inspect", "-f",
                 "{{.Name}} {{.State.Status}} {{.State.ExitCode}}", *ids).stdout
        return {n.lstrip("/"): (s, int(c)) for n, s, c in (ln.split() for ln in out.splitlines())}

    def leftovers(self) -> str:
        label = f"label=com.docker.compose.project={self.name}"
        return "".join(sh("docker", kind, "ls", "-q", "--filter", label).stdout
                       for kind in ("container", "network", "volume"))


@pytest.fixture
def project(request: pytest.FixtureRequest) -> Iterator[Project]:
    # the engine install and image build began with the session (tests/docker_build.py)
    build_s = docker_build.build_for(request.config).wait(BUILD_TIMEOUT_S)
    print(f"engine + image build: {build_s:.0f} s since the session began")
    env = dict(os.environ, SPACEMAP_SIM_TIME=str(SIM_TIME_S), SPACEMAP_ROBOTS=str(ROBOTS),
               SPACEMAP_RUN=RUN, SPACEMAP_PORT=str(free_port()), SPACEMAP_SEED="0")
    proj = Project(env)
    try:
        yield proj
    finally:
        print(proj("logs", "--no-color", "--tail", "30", check=False).stdout[-8000:])
        proj("down", "--volumes", "--remove-orphans", "--timeout", "10", check=False)
    assert proj.leftovers() == "", f"compose down left {proj.leftovers()}"


def test_compose_up_runs_the_mission(project: Project, tmp_path: Path) -> None:
    started = time.monotonic()
    project("up", "-d", "--no-build", timeout=600)
    recorder = project.containers("recorder")
    assert len(recorder) == 1
    assert len(project.containers("agent")) == ROBOTS
    containers = project.containers()

    def recorded() -> bool:
        states = project.states(containers)
        failed = {n: s for n, s in states.items() if s[0] == "exited" and s[1] != 0}
        assert not failed, (f"containers failed: {failed}\n"
                            + project("logs", "--no-color", "--tail", "40").stdout[-6000:])
        return any("recorder" in n and s == ("exited", 0) for n, s in states.items())

    wait_for(recorded, MISSION_DEADLINE_S, "the recorder's run folder", poll_s=3.0)
    wall_s = time.monotonic() - started

    # the run folder is in the `runs` volume; copy it out as a user would
    sh("docker", "cp", f"{recorder[0]}:/runs/{RUN}", str(tmp_path))
    run_dir = tmp_path / RUN
    metrics = json.loads((run_dir / "metrics.json").read_text())
    missing = [k for k in METRICS_KEYS if k not in metrics]
    assert not missing, f"metrics.json lacks {missing}"
    assert metrics["robots"] == ROBOTS and metrics["world"] == "house"
    assert metrics["sim_time_s"] >= SIM_TIME_S - 1 or metrics["completed"], metrics
    assert metrics["coverage_3d_pct"] > COVERAGE_3D_FLOOR, metrics["coverage_3d_pct"]
    assert metrics["total_distance_m"] > 1.0, metrics["total_distance_m"]
    for robot in range(ROBOTS):  # every replica's robot mapped, watched from the first tick
        assert (run_dir / f"robot_{robot}_map.ply").exists(), robot
        stamps = [float(line.split()[0]) for line in
                  (run_dir / f"trajectory_{robot}_gt.tum").read_text().splitlines()]
        assert stamps[0] < 0.15 and stamps[-1] >= metrics["sim_time_s"] - 1, (robot, stamps[-1])

    # logs readable with `compose logs`: each agent replica logs its claimed robot id
    logs = project("logs", "--no-color", "agent").stdout
    claimed = sorted(int(line.split("robot id ")[1].split()[0])
                     for line in logs.splitlines() if "(--robot auto)" in line)
    assert claimed == list(range(ROBOTS)), claimed
    print(f"compose mission: {wall_s:.0f} s wall (up -d to run folder), "
          f"3D coverage {metrics['coverage_3d_pct']:.1f} %")
