"""The edge keeps freed memory for reuse (services/common/heap.py)."""

from __future__ import annotations

import subprocess
import sys

CHILD = """
import resource
import sys
import numpy as np
from services.common.heap import keep_freed_memory

if sys.argv[1] == "keep":
    assert keep_freed_memory()
for _ in range(2):  # the second array may reuse the first one's memory
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    a = np.ones(25_000_000)  # 200 MB, every page touched
    assert a.sum() == 25_000_000
    del a
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def faults_of_second_array(mode: str) -> int:
    done = subprocess.run([sys.executable, "-c", CHILD, mode], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    return int(done.stdout.split()[-1])


def test_a_freed_large_array_is_reused_without_page_faults() -> None:
    # in children: the setting is process-wide. By default glibc unmaps a freed 200 MB array
    # and the next one faults its pages in again: at least 100 faults (2 MB huge pages), up
    # to 50k (4 kB pages); kept, the pages are still there
    default, kept = faults_of_second_array("default"), faults_of_second_array("keep")
    assert kept < 50 and default >= 100
