"""The compose test's image build, started in the background when the session begins.

A cold build (engine install, debootstrap, wheelhouse, `docker build`) is mostly downloads
and disk work, minutes that would otherwise add to the suite's time: tests/conftest.py starts
it as soon as the `docker` tests are collected (and moves them to the end of the session), and
tests/test_compose_up.py waits for it with a deadline.
"""

from __future__ import annotations

import os
import signal
import subprocess
import tempfile
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BUILD_KEY = pytest.StashKey["Build"]()
COMMAND = "bash scripts/docker-engine.sh && bash scripts/docker-build.sh"


class Build:
    """`scripts/docker-engine.sh && scripts/docker-build.sh`, niced, logging to a file."""

    def __init__(self) -> None:
        self.log = Path(tempfile.mkstemp(prefix="spacemap-docker-build-", suffix=".log")[1])
        self.started = time.monotonic()
        with self.log.open("w") as out:
            self.proc = subprocess.Popen(
                ["nice", "-n", "10", "bash", "-c", COMMAND], cwd=REPO, stdout=out,
                stderr=subprocess.STDOUT, start_new_session=True)

    def wait(self, timeout_s: float) -> float:
        """Wait for the build to end; fail with its log unless it succeeded. Returns its wall
        time in seconds."""
        try:
            code = self.proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.stop()
            pytest.fail(f"the image build ran past {timeout_s:.0f} s:\n{self.tail()}")
        assert code == 0, f"`{COMMAND}` failed ({code}):\n{self.tail()}"
        return time.monotonic() - self.started

    def tail(self, chars: int = 6000) -> str:
        return self.log.read_text(errors="replace")[-chars:]

    def stop(self) -> None:
        """End the build if it still runs; drop its log when it succeeded."""
        if self.proc.poll() == 0:
            self.log.unlink(missing_ok=True)
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()


def schedule(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Move the `docker` tests last and start their build now (once per session)."""
    docker = [item for item in items if item.get_closest_marker("docker")]
    if not docker or config.option.collectonly or BUILD_KEY in config.stash:
        return
    items[:] = [item for item in items if not item.get_closest_marker("docker")] + docker
    config.stash[BUILD_KEY] = Build()


def build_for(config: pytest.Config) -> Build:
    """The session's build (started now if the hook did not, e.g. under another runner)."""
    if BUILD_KEY not in config.stash:
        config.stash[BUILD_KEY] = Build()
    return config.stash[BUILD_KEY]


def stop(config: pytest.Config) -> None:
    build = config.stash.get(BUILD_KEY, None)
    if build is not None:
        build.stop()
