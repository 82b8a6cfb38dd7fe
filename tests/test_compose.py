"""docker-compose.yml and the Dockerfile, checked statically (tests/test_compose_up.py runs
them on a Docker engine).

Every service's command and health check must parse as a real `spacemap` CLI invocation, and
every environment variable must map to a field of the mission config; compose's `${VAR:-default}`
variables are read with their defaults.
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

VARIABLE = re.compile(r"\$\{([A-Z0-9_]+):-([^}]*)\}")
COMPOSE_TEXT = (REPO / "docker-compose.yml").read_text()
COMPOSE = yaml.safe_load(VARIABLE.sub(lambda m: m.group(2), COMPOSE_TEXT))
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
    assert {"router", "sim", "edge", "agent", "recorder"} <= set(SERVICES)
    for name, service in SERVICES.items():
        for dep in service.get("depends_on", {}):
            assert dep in SERVICES, f"{name} depends on unknown {dep}"
    assert "runs" in COMPOSE["volumes"]
    assert all("runs:/runs" in s["volumes"] for s in SERVICES.values())


@pytest.mark.parametrize("name", sorted(SERVICES))
def test_command_is_real_cli(name: str) -> None:
    ctx = parse_cli(SERVICES[name]["command"])
    if ctx.info_name == "agent":
        assert ctx.params["robot"] == "auto"


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
    assert config.bus.connect == "tls/router:7447" and config.bus.tls
    assert config.sim.robots == 3


def test_dockerfile() -> None:
    text = (REPO / "Dockerfile").read_text()
    # the base is a build argument, by default the public slim image
    assert re.search(r"^ARG BASE=python:3\.11-slim-bookworm$", text, re.M)
    assert re.findall(r"^FROM .*$", text, re.M) == ["FROM ${BASE}"]
    assert not re.search(r"^# syntax=", text, re.M), "a frontend image would need a registry"
    for pkg in ("libusb-1.0-0", "libgl1", "libegl1", "libgl1-mesa-dri", "libosmesa6"):
        assert pkg in text, f"Dockerfile does not install {pkg}"
        assert pkg in (REPO / "scripts" / "docker-base.sh").read_text(), pkg
    # the wheelhouse and the source are bind-mounted, never copied into a layer
    assert not re.search(r"^(COPY|ADD) ", text, re.M)
    assert "--mount=type=bind,source=wheelhouse,target=/wheels" in text
    for path in ("pyproject.toml", "README.md", "schemas", "services"):
        assert f"--mount=type=bind,source={path},target=/src/{path}" in text, path
    for path in ("pyproject.toml", "schemas", "services", "wheelhouse/README.md"):
        assert (REPO / path).exists(), path
    # offline: only the wheelhouse, never an index
    assert text.count('OFFLINE" = 1 ]; then idx="--no-index"') == 2
    assert text.count("--find-links /wheels") == 2
    entry = re.search(r"^ENTRYPOINT (\[.*\])", text, re.M)
    assert entry and yaml.safe_load(entry.group(1)) == ["spacemap"]
    builds = [s.get("build") for s in SERVICES.values()]
    assert all(b == {"context": ".", "args": {"BASE": "python:3.11-slim-bookworm"}}
               for b in builds), builds
    ignored = (REPO / ".dockerignore").read_text().split()
    assert "wheelhouse" not in ignored and ".venv" in ignored


def test_sim_waits_for_every_watcher() -> None:
    """The clock starts only when the edge, the agents and the recorder are on the bus: a
    recorder that joined late would miss the mission's start (seen: a 10 s mission over before
    the recorder had built its ground truth)."""
    deps = SERVICES["sim"]["depends_on"]
    for name in ("edge", "agent", "recorder"):
        assert deps[name] == {"condition": "service_healthy"}, name
        assert "healthcheck" in SERVICES[name], name


def test_one_variable_sets_the_fleet() -> None:
    """SPACEMAP_ROBOTS sizes the logins, the simulated fleet and the agent replicas together;
    SPACEMAP_WORLD picks the world; the README documents both."""
    uses = {m.group(1): m.group(2) for m in VARIABLE.finditer(COMPOSE_TEXT)}
    assert uses["SPACEMAP_ROBOTS"] == "3" and uses["SPACEMAP_WORLD"] == "house"
    robots = re.findall(r"^\s*(.*)\$\{SPACEMAP_ROBOTS:-3\}", COMPOSE_TEXT, re.M)
    assert any("--robots" in line for line in robots)
    assert any("SPACEMAP__SIM__ROBOTS" in line for line in robots)
    assert any("replicas" in line for line in robots)
    assert SERVICES["agent"]["deploy"]["replicas"] == 3
    readme = (REPO / "README.md").read_text()
    for var in uses:
        assert var in readme, f"README does not document {var}"


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
            role, login = test[test.index("--role") + 1], test[test.index("--as") + 1]
            ident = test[test.index("--id") + 1] if "--id" in test else "0"
            expected = {"agent": "auto" if ident == "auto" else f"agent-{ident}",
                        "router": "monitor"}.get(role, role)
            assert login == expected, name
