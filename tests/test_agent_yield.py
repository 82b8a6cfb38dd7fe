"""Yielding to a teammate ahead, and the detour that ends two robots yielding face to face."""

from __future__ import annotations

from schemas.messages import Pose2D, RobotPose
from services.robot_agent.agent import AgentCore
from services.robot_agent.config import AgentConfig
from services.robot_agent.navigation import Command

N = 10  # yield_detour_ticks


def yield_command(core: AgentCore, pose_world: tuple[float, float, float], cmd: Command,
                  tick: int) -> Command:
    """The agent's yield rule applied to `cmd` at `pose_world` with its teammates."""
    return core.yields.command(cmd, pose_world, core.teammates, core.teammates_prev, core.nav,
                               tick)


def test_robots_face_to_face_plan_around_each_other_by_default() -> None:
    """The default: a wait ends in a detour, not in goals the validator ends one by one."""
    assert AgentConfig().yield_detour_ticks > 0
    core = AgentCore(AgentConfig(), 2, 0.1, team_size=1)
    assert _ticks_until_detour(core, teammate=1) == AgentConfig().yield_detour_ticks


def _core(robot_id: int, detour_ticks: int = N) -> AgentCore:
    core = AgentCore(AgentConfig(yield_detour_ticks=detour_ticks), robot_id, 0.1, team_size=1)
    return core


def _ahead(core: AgentCore, teammate: int, tick: int) -> None:
    core.on_pose(RobotPose(robot_id=teammate, tick=tick, stamp_ns=tick * 10**8,
                           pose_world=Pose2D(x=0.5, y=0.0, yaw=3.14)))


def _ticks_until_detour(core: AgentCore, teammate: int, limit: int = 100) -> int | None:
    for tick in range(limit):
        _ahead(core, teammate, tick)
        cmd = yield_command(core, (0.0, 0.0, 0.0), Command(0.5, 0.1), tick)
        assert cmd == Command(0.0, 0.1)  # forward motion stopped, turning kept
        if core.nav.avoid_xy is not None:
            return tick
    return None


def test_the_higher_id_detours_first_the_lower_id_later() -> None:
    assert _ticks_until_detour(_core(robot_id=2), teammate=1) == N
    assert _ticks_until_detour(_core(robot_id=1), teammate=2) == 3 * N


def test_no_detour_when_off_and_none_without_a_teammate_ahead() -> None:
    assert _ticks_until_detour(_core(robot_id=2, detour_ticks=0), teammate=1) is None
    core = _core(robot_id=2)
    assert yield_command(core, (0.0, 0.0, 3.14), Command(0.5, 0.0), 0) == Command(0.5, 0.0)
