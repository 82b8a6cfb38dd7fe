"""Robot ids for agents started as identical replicas (`docker compose` scaling one `agent`
service): each replica claims the lowest free robot id in a folder every replica shares.

A claim is a file `robot-{id}` created exclusively (O_EXCL: atomic on one host's file system)
holding its holder's name (the container's host name, stable across restarts of that
container), so a restarted replica gets its own id back. `spacemap credentials` starts a fleet
afresh and forgets earlier claims (`reset_claims`).
"""

from __future__ import annotations

import os
import shutil
import socket
from pathlib import Path

CLAIMS = "claims"  # subfolder of the credentials folder


def claims_folder(credentials: str | Path) -> Path:
    return Path(credentials) / CLAIMS


def reset_claims(credentials: str | Path) -> None:
    shutil.rmtree(claims_folder(credentials), ignore_errors=True)


def holder_name() -> str:
    """This process's holder name: the host name (a container's id under Docker)."""
    return socket.gethostname()


def claimed_robot(folder: Path, holder: str) -> int | None:
    """The robot id `holder` claimed earlier, if any."""
    for path in sorted(folder.glob("robot-*")):
        try:
            if path.read_text().strip() == holder:
                return int(path.name.removeprefix("robot-"))
        except (OSError, ValueError):
            continue
    return None


def claim_robot(folder: Path, robots: int, holder: str) -> int:
    """Holder's robot id: its earlier claim, else the lowest id in [0, robots) nobody holds.
    Raises RuntimeError when every id is held by another."""
    folder.mkdir(parents=True, exist_ok=True)
    earlier = claimed_robot(folder, holder)
    if earlier is not None:
        return earlier
    for robot in range(robots):
        try:
            fd = os.open(folder / f"robot-{robot}", os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        except FileExistsError:
            continue
        with os.fdopen(fd, "w") as out:
            out.write(holder + "\n")
        return robot
    raise RuntimeError(f"all {robots} robot ids in {folder} are claimed: more agent replicas "
                       "than robots, or claims left from another fleet (run `spacemap "
                       "credentials` again)")


def resolve_robot(value: str, credentials: str | None, robots: int, claim: bool) -> int | None:
    """`--robot`/`--id` as given: a number, or `auto` (this replica's id from the claims in
    the credentials folder; claims one when `claim`, else None while it has none)."""
    if value != "auto":
        robot = int(value)
        if robot < 0:
            raise ValueError(f"robot id must be ≥ 0, got {robot}")
        return robot
    if not credentials:
        raise ValueError("--robot auto needs bus.credentials (the shared folder of claims)")
    folder = claims_folder(credentials)
    if claim:
        return claim_robot(folder, robots, holder_name())
    return claimed_robot(folder, holder_name()) if folder.is_dir() else None
