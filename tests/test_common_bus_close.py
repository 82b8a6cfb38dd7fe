"""A bus counts the bad messages still queued when it closes: nothing goes uncounted."""

from __future__ import annotations

import zenoh

from schemas.messages import Clock
from services.common.bus import Bus, BusConfig, zenoh_config


def test_close_validates_what_was_never_polled() -> None:
    config = BusConfig()
    with zenoh.open(zenoh_config("peer", listen=[])) as session:
        bus = Bus(session, config)
        key = bus.keys.clock()
        bus.inbox.put(("msg", key, b"\x93not a clock", Clock))
        bus.inbox.put(("msg", key, b"", Clock))
        assert bus.dropped.total() == 0
        bus.close()
        assert bus.dropped.total() == 2
        assert bus.inbox.empty()
