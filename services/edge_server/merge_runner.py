"""Where the merger's update runs: in the planner's own thread, or in a worker process.

A plan spends about a third of its time in the pose-graph merger (prechecks, small_gicp
registrations, GTSAM), and at L = 0 the lockstep clock waits for the whole plan while the
second core idles. `WorkerMerges` runs the update in a child process on a replica of the
submap store, which gets every Submap message and every correction in the planner's order,
so the update is the same function of the same inputs and returns the same poses. Meanwhile
the planner brings P* and Alg. 1's sums up to date with the new data and surveys it
(planner.py, `_merge_and_survey`), again after a correction.
A thread cannot do this: small_gicp holds the GIL while it registers (docs/benchmarks.md).

Both runners answer `finish` with the submaps whose pose changed and, for each robot with
one, all of its submaps' estimates (what a `Correction` carries).
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing as mp
import signal
import traceback
import weakref
from multiprocessing.connection import Connection
from typing import Any, Protocol

import numpy as np

from schemas.messages import Submap
from services.edge_server.merger import MapMerger, MergerParams
from services.edge_server.submap_store import SubmapKey, SubmapStore

log = logging.getLogger(__name__)

Estimates = dict[int, tuple[list[int], np.ndarray]]  # robot → (submap ids, (n, 4, 4) poses)
CLOSE_TIMEOUT_S = 5.0


class Merges(Protocol):
    concurrent: bool  # True: `start` returns at once and the update runs beside the caller

    def submap(self, msg: Submap) -> None:
        """A Submap message the planner's store just applied."""

    def start(self, store: SubmapStore) -> None:
        """Begin the update on the store as it is now."""

    def finish(self, store: SubmapStore) -> tuple[dict[SubmapKey, np.ndarray], Estimates]:
        """The update's changed poses and estimates, once done; the store is not touched."""

    def summary(self) -> str:
        """The merger's closing log line."""

    def close(self) -> None:
        """Release what the runner holds."""


def estimates_of(merger: MapMerger, changed: dict[SubmapKey, np.ndarray]) -> Estimates:
    """Every submap estimate of each robot with a changed pose, ids in order."""
    out: Estimates = {}
    for robot in sorted({r for r, _ in changed}):
        ids = sorted(s for r, s in merger.estimates if r == robot)
        out[robot] = (ids, np.stack([merger.estimates[(robot, s)] for s in ids]))
    return out


class LocalMerges:
    """The update in the caller's thread, when the plan asks for its result."""

    concurrent = False

    def __init__(self, voxel_m: float, params: MergerParams) -> None:
        self.merger = MapMerger(voxel_m, params)

    def submap(self, msg: Submap) -> None:
        pass  # the merger reads the planner's own store

    def start(self, store: SubmapStore) -> None:
        pass

    def finish(self, store: SubmapStore) -> tuple[dict[SubmapKey, np.ndarray], Estimates]:
        changed = self.merger.update(store)
        return changed, estimates_of(self.merger, changed)

    def summary(self) -> str:
        return self.merger.report_step_summary()

    def close(self) -> None:
        pass


class WorkerMerges:
    """The update in a spawned child process with its own store replica and merger."""

    concurrent = True

    def __init__(self, voxel_m: float, params: MergerParams) -> None:
        ctx = mp.get_context("spawn")  # the edge runs zenoh's threads: never fork it
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=serve, args=(child, voxel_m, params), daemon=True,
                                 name="edge-merger")
        self._proc.start()
        child.close()
        self._running = False
        self._finalizer = weakref.finalize(self, _shut, self._conn, self._proc)

    def submap(self, msg: Submap) -> None:
        self._send("submap", msg)

    def start(self, store: SubmapStore) -> None:
        self._send("update", None)
        self._running = True

    def finish(self, store: SubmapStore) -> tuple[dict[SubmapKey, np.ndarray], Estimates]:
        if not self._running:
            self.start(store)
        self._running = False
        return self._answer()

    def summary(self) -> str:
        self._send("summary", None)
        return self._answer()

    def _send(self, kind: str, body: Any) -> None:
        try:
            self._conn.send((kind, body))
        except (BrokenPipeError, OSError) as exc:
            raise self._died() from exc

    def _answer(self) -> Any:
        try:
            kind, body = self._conn.recv()
        except (EOFError, OSError) as exc:
            raise self._died() from exc
        if kind == "error":
            raise RuntimeError(f"the merger's worker process failed:\n{body}")
        return body

    def _died(self) -> RuntimeError:
        self._proc.join(0.1)
        return RuntimeError(f"the merger's worker process died (exit code {self._proc.exitcode})")

    def close(self) -> None:
        self._finalizer()


def _shut(conn: Connection, proc: mp.process.BaseProcess) -> None:
    with contextlib.suppress(BrokenPipeError, OSError):  # already gone
        conn.send(("close", None))
    proc.join(CLOSE_TIMEOUT_S)
    if proc.is_alive():
        proc.terminate()
        proc.join(CLOSE_TIMEOUT_S)
    conn.close()


def serve(conn: Connection, voxel_m: float, params: MergerParams) -> None:
    """The worker's loop: apply submaps, run updates (and the correction each implies on the
    replica, as the planner does on its store), until "close" or the pipe closes. One answer
    per request; a submap that failed to apply is reported by the next one."""
    # Ctrl-C and a process group's SIGTERM reach the worker too: the edge decides when it
    # ends (its pipe closes when the edge exits, however it exits)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    store = SubmapStore(voxel_m)
    merger = MapMerger(voxel_m, params)
    failed: str | None = None
    while True:
        try:
            kind, body = conn.recv()
        except EOFError:
            return
        if kind == "close":
            return
        try:
            if kind == "submap":
                store.apply(body)
            elif failed is not None:
                conn.send(("error", failed))
            elif kind == "update":
                changed = merger.update(store)
                for key in sorted(changed):
                    store.set_pose(key, changed[key])
                conn.send(("ok", (changed, estimates_of(merger, changed))))
            elif kind == "summary":
                conn.send(("ok", merger.report_step_summary()))
        except Exception:  # the parent raises it: a merger bug must not hang the plan
            failed = traceback.format_exc()
            if kind != "submap":
                conn.send(("error", failed))
