"""The one place that builds bus keys (SPEC §2). Every key starts with the mission prefix."""

from __future__ import annotations

from dataclasses import dataclass

DEFAULT_PREFIX = "spacemap"
ROLES = ("router", "sim", "edge", "agent", "monitor")


@dataclass(frozen=True)
class Keys:
    prefix: str = DEFAULT_PREFIX

    def __post_init__(self) -> None:
        if not self.prefix or any(c in self.prefix for c in "*$?#") or self.prefix.endswith("/"):
            raise ValueError(f"invalid key prefix {self.prefix!r}")

    def _k(self, *parts: object) -> str:
        return "/".join((self.prefix, *map(str, parts)))

    def clock(self) -> str:
        return self._k("sim", "clock")

    def rgbd(self, robot: int | str) -> str:
        return self._k("robot", robot, "rgbd")

    def odom(self, robot: int | str) -> str:
        return self._k("robot", robot, "odom")

    def cmd_vel(self, robot: int | str) -> str:
        return self._k("robot", robot, "cmd_vel")

    def pose(self, robot: int | str) -> str:
        return self._k("robot", robot, "pose")

    def submap(self, robot: int | str) -> str:
        return self._k("robot", robot, "submap")

    def correction(self, robot: int | str) -> str:
        return self._k("robot", robot, "correction")

    def goal(self, robot: int | str) -> str:
        return self._k("robot", robot, "goal")

    def goal_status(self, robot: int | str) -> str:
        return self._k("robot", robot, "goal_status")

    def map_grid(self) -> str:
        return self._k("map", "grid")

    def map_frontiers(self) -> str:
        return self._k("map", "frontiers")

    def map_cloud(self) -> str:
        return self._k("map", "cloud")

    def inventory(self, robot: int | str) -> str:
        """Queryable on agent `robot`: its own submap Inventory (spacemap's addition)."""
        return self._k("robot", robot, "inventory")

    def map_inventory(self) -> str:
        """Queryable on the edge: the Inventory of every submap it merged (spacemap's addition)."""
        return self._k("map", "inventory")

    def map_robot_grid(self) -> str:
        """Queryable: GridRequest → one robot's own OccupancyGrid (spacemap's addition)."""
        return self._k("map", "robot_grid")

    def edge_ack(self) -> str:
        return self._k("edge", "ack")

    def gt_pose(self, robot: int | str) -> str:
        return self._k("eval", "robot", robot, "gt_pose")

    def any_robot(self, topic: str) -> str:
        """Wildcard over every robot's `topic` (e.g. "pose")."""
        return self._k("robot", "*", topic)

    def alive_all(self) -> str:
        return self._k("alive", "**")

    def alive(self, role: str, ident: int | str = 0) -> str:
        if role not in ROLES:
            raise ValueError(f"unknown role {role!r}")
        return self._k("alive", role, ident)

    def robot_id(self, key: str) -> int:
        """The robot id in a `.../robot/{id}/...` key; ValueError when there is none."""
        parts = key.split("/")
        try:
            return int(parts[parts.index("robot") + 1])
        except (ValueError, IndexError) as exc:
            raise ValueError(f"no robot id in key {key!r}") from exc

    def alive_member(self, key: str) -> tuple[str, str]:
        """(role, id) of an `alive/{role}/{id}` key."""
        parts = key.split("/")
        i = parts.index("alive")
        return parts[i + 1], parts[i + 2]


@dataclass(frozen=True)
class RoleKeys:
    """The keys one process may use, by action: the source of the router's access control
    (services/common/access.py). Wildcards are written exactly as the services declare them."""

    publish: tuple[str, ...] = ()
    subscribe: tuple[str, ...] = ()
    serve: tuple[str, ...] = ()  # queryables it declares and answers
    query: tuple[str, ...] = ()  # queryables it asks
    token: tuple[str, ...] = ()  # its own liveliness token


def role_keys(keys: Keys, role: str, ident: int, robots: int) -> RoleKeys:
    """Which keys process (`role`, `ident`) of a mission with `robots` robots may use: the
    key table of ARCHITECTURE.md, one home. The tools (`health`, `inventory`) run as
    `monitor`; every role may also read liveliness (`alive/**`)."""
    ids = range(robots)
    token = (keys.alive(role, ident),)
    if role == "sim":
        return RoleKeys(
            publish=(keys.clock(), *(f(i) for i in ids for f in (keys.gt_pose, keys.rgbd,
                                                                  keys.odom))),
            subscribe=(keys.any_robot("cmd_vel"), keys.edge_ack(), keys.map_frontiers()),
            token=token,
        )
    if role == "edge":
        return RoleKeys(
            publish=(keys.map_grid(), keys.map_frontiers(), keys.edge_ack(),
                     *(f(i) for i in ids for f in (keys.goal, keys.correction))),
            subscribe=(keys.clock(), *(keys.any_robot(t) for t in ("submap", "pose",
                                                                    "goal_status"))),
            serve=(keys.map_cloud(), keys.map_robot_grid(), keys.map_inventory()),
            token=token,
        )
    if role == "agent":
        if not 0 <= ident < robots:
            raise ValueError(f"agent {ident} is not one of {robots} robots")
        r = ident
        return RoleKeys(
            publish=(keys.pose(r), keys.submap(r), keys.cmd_vel(r), keys.goal_status(r)),
            subscribe=(keys.rgbd(r), keys.odom(r), keys.goal(r), keys.correction(r),
                       keys.map_grid(), keys.any_robot("pose")),
            serve=(keys.inventory(r),),
            token=token,
        )
    if role == "monitor":  # the launcher's recorder, sampler and live view; the CLI tools
        return RoleKeys(
            subscribe=(keys.clock(), keys.map_grid(), keys.map_frontiers(), keys.edge_ack(),
                       keys.gt_pose("*"),
                       *(keys.any_robot(t) for t in ("pose", "goal", "goal_status", "submap",
                                                     "cmd_vel", "rgbd"))),
            query=(keys.map_cloud(), keys.map_robot_grid(), keys.map_inventory(),
                   keys.inventory("*")),
            token=token,
        )
    raise ValueError(f"role {role!r} has no keys of its own")
