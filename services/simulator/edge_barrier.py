"""Which edge answers the lockstep clock must hold before it steps a tick (pure, no bus).

With pipelining (`sim.edge_pipeline_ticks` = L) the edge's plan for edge tick k is due at
tick k + L instead of tick k: the simulator publishes ticks k … k + L − 1 without waiting, so
the agents and the simulator work while the edge plans, and at tick k + L it waits for
EdgeAck(k). Everything the edge published for tick k (it publishes before its ack) has then
reached every subscriber before Clock(k + L + 1), which is why the agents apply the edge's
outputs of tick k from tick k + L + 1 on, and why the same seed gives the same run.
"""

from __future__ import annotations


class EdgeBarrier:
    """Edge ticks published while the edge was alive and not yet answered."""

    def __init__(self, every_ticks: int, lag_ticks: int) -> None:
        self.every = every_ticks
        self.lag = lag_ticks
        self.waiting: set[int] = set()

    def published(self, tick: int, edge_alive: bool) -> None:
        """Clock(tick) went out; an edge that was alive then will answer it."""
        if edge_alive and tick % self.every == 0:
            self.waiting.add(tick)

    def acked(self, tick: int) -> None:
        self.waiting.discard(tick)

    def edge_gone(self) -> None:
        """A dead edge answers nothing: no tick waits for it (a restarted one joins at its
        next edge tick)."""
        self.waiting.clear()

    def blocking(self, tick: int) -> list[int]:
        """The edge ticks whose answers are due before `tick` may be stepped."""
        return sorted(k for k in self.waiting if k + self.lag <= tick)

    def stop_tick(self, complete_tick: int) -> int:
        """The tick the clock stops at after the edge declared completion at `complete_tick`:
        the one at which that plan's answer is due, so the stop does not depend on when the
        verdict arrived."""
        return complete_tick + self.lag
