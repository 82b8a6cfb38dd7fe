"""CPU accounting of the mission's processes (profile.json, bench/bench_mission.py)."""

from __future__ import annotations

import os
import subprocess
import sys
import time

from services.processes import process_cpu_seconds


def test_cpu_seconds_of_a_busy_process_grow_and_of_a_gone_one_are_none() -> None:
    child = subprocess.Popen([sys.executable, "-c", "sum(i * i for i in range(3_000_000))"])
    child.wait()
    assert process_cpu_seconds(child.pid) is None  # reaped: no /proc entry
    before = process_cpu_seconds(os.getpid())
    assert before is not None
    sum(i * i for i in range(3_000_000))  # burn some CPU here
    after = process_cpu_seconds(os.getpid())
    assert after is not None and after > before


def test_cpu_seconds_count_a_process_s_live_children() -> None:
    """The edge's merger worker is the edge's child: its CPU is the edge's."""
    script = ("import subprocess, sys\n"
              "c = subprocess.Popen([sys.executable, '-c', 'while True: pass'])\n"
              "c.wait()\n")
    parent = subprocess.Popen([sys.executable, "-c", script])
    try:
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline:
            cpu = process_cpu_seconds(parent.pid)
            if cpu is not None and cpu > 1.0:  # the parent itself only waits
                break
            time.sleep(0.1)
        assert cpu is not None and cpu > 1.0
    finally:
        for pid in _descendants(parent.pid):
            os.kill(pid, 9)
        parent.kill()
        parent.wait()


def _descendants(pid: int) -> list[int]:
    from services.processes import _children

    out = []
    for child in _children(pid):
        out += [child, *_descendants(child)]
    return out
