"""EdgeBarrier: which edge ticks the lockstep clock waits for, with and without pipelining."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from services.simulator.config import SimConfig
from services.simulator.edge_barrier import EdgeBarrier


def test_without_pipelining_edge_tick_k_is_due_at_k() -> None:
    barrier = EdgeBarrier(every_ticks=10, lag_ticks=0)
    barrier.published(9, edge_alive=True)
    assert barrier.blocking(9) == []  # not an edge tick
    barrier.published(10, edge_alive=True)
    assert barrier.blocking(10) == [10]
    barrier.acked(10)
    assert barrier.blocking(10) == []
    assert barrier.stop_tick(10) == 10


def test_with_pipelining_edge_tick_k_is_due_at_k_plus_lag() -> None:
    barrier = EdgeBarrier(every_ticks=10, lag_ticks=4)
    barrier.published(10, edge_alive=True)
    assert [barrier.blocking(t) for t in range(10, 14)] == [[], [], [], []]
    assert barrier.blocking(14) == [10] and barrier.blocking(19) == [10]
    barrier.acked(10)
    assert barrier.blocking(14) == []
    assert barrier.stop_tick(10) == 14


def test_an_edge_that_was_not_alive_or_died_is_not_waited_for() -> None:
    barrier = EdgeBarrier(every_ticks=10, lag_ticks=2)
    barrier.published(10, edge_alive=False)
    assert barrier.blocking(12) == []
    barrier.published(20, edge_alive=True)
    barrier.edge_gone()
    assert barrier.blocking(22) == []


def test_pipeline_must_leave_one_plan_in_flight() -> None:
    assert SimConfig(edge_pipeline_ticks=4).edge_lag_ticks == 4
    assert SimConfig(edge_pipeline_ticks=4, realtime=1.0).edge_lag_ticks == 0
    assert SimConfig().edge_lag_ticks == 0  # default: the fleet waits for every plan
    none = {"edge_pipeline_ticks": None}  # None: the whole planning period
    assert SimConfig(**none).edge_lag_ticks == 9
    assert SimConfig(edge_every_ticks=4, **none).edge_lag_ticks == 3
    with pytest.raises(ValidationError):
        SimConfig(edge_pipeline_ticks=10)
