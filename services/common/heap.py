"""Keep the memory a process frees for its own reuse, instead of handing it back to the kernel.

glibc serves an allocation above its mmap threshold (at most 32 MB) with a fresh mapping and
unmaps it when freed, so a process that allocates and frees arrays of hundreds of MB on
every cycle takes a page fault for every 4 kB of each one again: the edge's plan, late in a
24-robot warehouse mission, copies arrays of millions of rows, and 18 % of its CPU time was
the kernel's (bench/bench_edge_replay.py; sys 103 s against 16 s with this). Allocations
then come from the heap, and a free heap top is trimmed only above `trim_bytes`.
"""

from __future__ import annotations

import ctypes
import logging

log = logging.getLogger(__name__)

_M_TRIM_THRESHOLD = -1
_M_MMAP_MAX = -4


def keep_freed_memory(trim_bytes: int = 1 << 30) -> bool:
    """Serve every allocation from the heap and keep up to `trim_bytes` of it free; True
    when set (glibc only; elsewhere nothing changes)."""
    try:
        libc = ctypes.CDLL("libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        log.info("not glibc: freed memory goes back to the system as usual")
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    return bool(mallopt(_M_MMAP_MAX, 0)) and bool(mallopt(_M_TRIM_THRESHOLD, trim_bytes))
