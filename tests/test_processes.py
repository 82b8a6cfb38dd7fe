"""CPU accounting of the mission's processes (profile.json, bench/bench_mission.py)."""

from __future__ import annotations

import os
import subprocess
import sys

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
