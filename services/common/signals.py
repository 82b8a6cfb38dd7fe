"""SIGTERM and SIGINT as a stop event, the way every service process ends."""

from __future__ import annotations

import signal
import threading


def stop_on_signals(stop: threading.Event | None = None) -> threading.Event:
    """Set `stop` (a new event if None) on SIGTERM or SIGINT. Outside the main thread (a service
    embedded in a test) signal handlers cannot be installed: the caller sets `stop` itself."""
    stop = stop or threading.Event()
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, lambda *_: stop.set())
    return stop
