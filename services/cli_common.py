"""What every `spacemap` command shares: option types, logging, the config from its sources."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import typer

from services.config import SpacemapConfig, load_config

ConfigOpt = Annotated[Path | None, typer.Option("--config", help="mission config YAML")]
ConnectOpt = Annotated[
    str | None, typer.Option("--connect", help="router endpoint, e.g. tcp/HOST:7447")
]
SetOpt = Annotated[
    list[str] | None, typer.Option("--set", help="override a config field: section.field=value")
]
LogOpt = Annotated[str, typer.Option("--log-level", help="DEBUG, INFO, WARNING")]
VIEW_TO_HELP = ("spawn[:PORT] (start a rerun viewer), serve[:PORT] (host a gRPC server that "
                "`rerun rerun+http://HOST:PORT/proxy` opens) or a viewer's rerun+http:// URL")


def setup_logging(level: str) -> None:
    logging.basicConfig(
        level=getattr(logging, level.upper(), logging.INFO),
        format="%(asctime)s %(processName)s %(name)s %(levelname)s: %(message)s",
    )


def parse_sets(sets: list[str] | None) -> dict[str, Any]:
    import yaml

    out: dict[str, Any] = {}
    for item in sets or []:
        if "=" not in item:
            raise typer.BadParameter(f"--set wants section.field=value, got {item!r}")
        key, raw = item.split("=", 1)
        out[key.strip()] = yaml.safe_load(raw)
    return out


@contextmanager
def tls_errors() -> Iterator[None]:
    """A missing or unusable certificate, or an endpoint that contradicts bus.tls: one line
    naming the file or the setting, exit status 2, no traceback."""
    from services.common.tls import TlsError

    try:
        yield
    except TlsError as exc:
        typer.echo(f"spacemap: {exc}", err=True)
        raise typer.Exit(2) from exc


def service_config(
    config: Path | None, connect: str | None, sets: list[str] | None
) -> SpacemapConfig:
    """YAML, then environment, then --set and --connect."""
    overrides = parse_sets(sets)
    if connect:
        overrides["bus.connect"] = connect
    try:
        return load_config(config, overrides)
    except (ValueError, OSError) as exc:
        raise typer.BadParameter(str(exc)) from exc
