"""Shared fixtures: where ../shared is, and a helper that finds leftover processes."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from services.processes import RUN_TAG_ENV

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
AWS_HOUSE = SHARED / "worlds" / "aws_small_house" / "small_house.xml"

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


@pytest.fixture
def aws_house() -> Path:
    if not AWS_HOUSE.exists():
        pytest.skip(f"the AWS small house is not at {AWS_HOUSE} (../shared is absent)")
    return AWS_HOUSE


def processes_tagged(run_logs: Path) -> list[int]:
    """PIDs of live (non-zombie) processes started for the run whose logs are in `run_logs`."""
    tag = f"{RUN_TAG_ENV}={run_logs.resolve()}".encode()
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            environ = (entry / "environ").read_bytes().split(b"\0")
            state = (entry / "stat").read_text().rsplit(")", 1)[1].split()[0]
        except (OSError, IndexError):
            continue
        if tag in environ and state != "Z":
            pids.append(int(entry.name))
    return pids


@pytest.hookimpl(trylast=True)  # after -k/-m deselection: no build for deselected tests
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    # the docker tests run last; their image build starts now and overlaps the rest
    from tests import docker_build

    docker_build.schedule(config, items)


def pytest_unconfigure(config: pytest.Config) -> None:
    from tests import docker_build

    docker_build.stop(config)
