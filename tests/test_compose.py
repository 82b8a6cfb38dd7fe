"""docker-compose.yml and the Dockerfile, checked statically (there is no Docker engine here).

Every service's command and health check must parse as a real `spacemap` CLI invocation, and
every environment variable must map to a field of the mission config.
"""

from __future__ import annotations

import re
import shlex
from typing import Any

import pytest
import typer.main
import yaml
from pydantic import BaseModel

from services.cli import app
from services.config import ENV_PREFIX, SpacemapConfig, load_config
from tests.conftest import REPO

COMPOSE = yaml.safe_load((REPO / "docker-compose.yml").read_text())
SERVICES: dict[str, dict[str, Any]] = COMPOSE["services"]
CLI = typer.main.get_command(app)


def parse_cli(argv: list[str]) -> Any:
    """Parse like the real CLI would (typer's own click); raises on unknown commands/options."""
    name, *rest = argv
    root = CLI.make_context("spacemap", [name], resilient_parsing=True)
    command = CLI.get_command(root, name)
    assert command is not None, f"`spacemap {name}` is not a command"
    return command.make_context(name, list(rest), parent=root)


def test_topology() -> None:
    assert {"router", "sim", "edge", "agent0", "agent1", "agent2"} <= set(SERVICES)
    for name, service in SERVICES.items():
        for dep in service.get("depends_on", {}):
            assert dep in SERVICES, f"{name} depends on unknown {dep}"
    assert "runs" in COMPOSE["volumes"]
    assert all("runs:/runs" in s["volumes"] for s in SERVICES.values())


@pytest.mark.parametrize("name", sorted(SERVICES))
def test_command_is_real_cli(name: str) -> None:
    ctx = parse_cli(SERVICES[name]["command"])
    if ctx.info_name == "agent":
        assert ctx.params["robot"] == int(name.removeprefix("agent"))


@pytest.mark.parametrize("name", sorted(n for n in SERVICES if "healthcheck" in SERVICES[n]))
def test_healthcheck_is_real_cli(name: str) -> None:
    test = SERVICES[name]["healthcheck"]["test"]
    assert test[:2] == ["CMD", "spacemap"]
    parse_cli(test[2:])


def _field_exists(model: type[BaseModel], path: list[str]) -> bool:
    head, *rest = path
    field = model.model_fields.get(head)
    if field is None:
        return False
    if not rest:
        return True
    sub = field.annotation
    return isinstance(sub, type) and issubclass(sub, BaseModel) and _field_exists(sub, rest)


@pytest.mark.parametrize("name", sorted(SERVICES))
def test_environment_maps_to_config(name: str) -> None:
    env = {k: str(v) for k, v in SERVICES[name].get("environment", {}).items()}
    assert env, f"{name} has no environment"
    for var in env:
        assert var.startswith(ENV_PREFIX), f"{var} is not a spacemap config variable"
        path = var[len(ENV_PREFIX):].lower().split("__")
        assert _field_exists(SpacemapConfig, path), f"{var} maps to no config field"
    config = load_config(environ=env)
    assert config.bus.connect == "tcp/router:7447"
    assert config.sim.robots == 3


def test_dockerfile() -> None:
    text = (REPO / "Dockerfile").read_text()
    assert re.search(r"^FROM python:3\.11", text, re.M)
    for pkg in ("libusb-1.0-0", "libegl1", "libgl1-mesa-dri", "libosmesa6"):
        assert pkg in text, f"Dockerfile does not install {pkg}"
    for path in ("pyproject.toml", "schemas", "services"):
        assert re.search(rf"^COPY .*\b{re.escape(path)}\b", text, re.M), path
        assert (REPO / path).exists()
    assert re.search(r"^RUN pip install .*\.$", text, re.M)
    entry = re.search(r"^ENTRYPOINT (\[.*\])", text, re.M)
    assert entry and yaml.safe_load(entry.group(1)) == ["spacemap"]
    build = {s.get("build") for s in SERVICES.values()}
    assert build == {"."} and (REPO / "Dockerfile").exists()


def test_readme_documents_separate_hosts() -> None:
    readme = (REPO / "README.md").read_text()
    blocks = "\n".join(re.findall(r"```bash\n(.*?)```", readme, re.S))
    commands = re.findall(r"^(?:\.venv/bin/)?spacemap (.*)$", blocks, re.M)
    assert any(c.startswith("agent") for c in commands), "README shows no `spacemap agent`"
    for line in commands:
        parse_cli(shlex.split(line.split("#")[0]))


def test_logins() -> None:
    """Every service logs in from the credentials volume, made for the compose fleet before
    the router starts; health checks log in as the process they probe."""
    made = parse_cli(SERVICES["credentials"]["command"])
    assert made.params["out"].as_posix() == "/credentials"
    assert made.params["robots"] == int(SERVICES["sim"]["environment"]["SPACEMAP__SIM__ROBOTS"])
    assert SERVICES["router"]["depends_on"]["credentials"] == {
        "condition": "service_completed_successfully"}
    for name, service in SERVICES.items():
        assert service["environment"]["SPACEMAP__BUS__CREDENTIALS"] == "/credentials", name
        assert "credentials:/credentials" in service["volumes"], name
        test = service.get("healthcheck", {}).get("test", [])
        if "--as" in test:
            role, ident = test[test.index("--role") + 1], test[test.index("--id") + 1]
            assert test[test.index("--as") + 1] == (f"agent-{ident}" if role == "agent"
                                                    else role), name
