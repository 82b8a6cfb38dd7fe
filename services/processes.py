"""Child processes of a mission: start each service as its own OS process, stop them all.

Children get PR_SET_PDEATHSIG so they die with the launcher even if it is SIGKILLed, and
they are stopped with SIGTERM, then SIGKILL after a grace period: no orphans.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

log = logging.getLogger(__name__)

_PR_SET_PDEATHSIG = 1
RUN_TAG_ENV = "SPACEMAP_RUN_LOGS"  # marks every child of a run, so leftovers can be found


def _die_with_parent() -> None:
    # Not on Linux: the launcher's own cleanup still runs.
    with contextlib.suppress(OSError):
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


def free_tcp_port() -> int:
    """A currently free TCP port on loopback."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def spacemap_command(*args: str) -> list[str]:
    """Command line that runs a `spacemap` subcommand with this interpreter."""
    return [sys.executable, "-m", "services", *args]


@dataclass
class ProcessGroup:
    """The mission's child processes, each logging to its own file."""

    log_dir: Path
    children: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)

    def start(self, name: str, argv: list[str], env: dict[str, str] | None = None) -> None:
        self.log_dir.mkdir(parents=True, exist_ok=True)
        out = open(self.log_dir / f"{name}.log", "wb")  # noqa: SIM115 - owned by the child
        child_env = {
            **os.environ,
            "OPENBLAS_NUM_THREADS": "1",
            RUN_TAG_ENV: str(self.log_dir.resolve()),
            **(env or {}),
        }
        self.children[name] = subprocess.Popen(
            argv, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            env=child_env, preexec_fn=_die_with_parent,
        )
        out.close()
        log.debug("started %s (pid %d): %s", name, self.children[name].pid, " ".join(argv))

    def cpu_seconds(self) -> dict[str, float]:
        """CPU time (user + system, all threads) each live child has used so far."""
        out = {}
        for name, proc in self.children.items():
            cpu = process_cpu_seconds(proc.pid) if proc.poll() is None else None
            if cpu is not None:
                out[name] = cpu
        return out

    def dead(self) -> dict[str, int]:
        """Children that have exited, with their exit codes."""
        return {n: p.returncode for n, p in self.children.items() if p.poll() is not None}

    def stop(self, grace_s: float = 10.0, order: list[str] | None = None) -> dict[str, int]:
        """SIGTERM every child (in `order` first), SIGKILL what is left after `grace_s`.

        The router goes last, once every client has closed its session: a router stopped
        while clients still hang up can take longer than the grace period to exit."""
        first = [n for n in (order or []) if n in self.children]
        names = first + [n for n in self.children if n not in first]
        clients = [n for n in names if n != "router"]
        self._terminate(clients, grace_s)
        self._terminate([n for n in names if n == "router"], grace_s)
        return {n: int(p.returncode) for n, p in self.children.items()}

    def _terminate(self, names: list[str], grace_s: float) -> None:
        for name in names:
            proc = self.children[name]
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + grace_s
        for name in names:
            proc = self.children[name]
            try:
                proc.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                log.warning("%s ignored SIGTERM; killing it", name)
                proc.kill()
                proc.wait()


def process_cpu_seconds(pid: int) -> float | None:
    """User + system CPU seconds of a running process and its live descendants (Linux
    /proc; the edge's merger worker is its child), None if the process is gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = stat[stat.rindex(")") + 2:].split()  # the name in () may contain spaces
    own = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime
    return own + sum(process_cpu_seconds(child) or 0.0 for child in _children(pid))


def _children(pid: int) -> list[int]:
    """Pids of a process's live children (every thread's list: a child belongs to the
    thread that started it)."""
    out: list[int] = []
    for path in Path(f"/proc/{pid}/task").glob("*/children"):
        try:
            out += [int(c) for c in path.read_text().split()]
        except OSError:
            continue
    return out

