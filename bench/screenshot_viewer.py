"""Screenshots of rerun's viewer on a finished recording (issue 16): the run folder's
mission.rrd in a headless rerun viewer, the time cursor at the end of the mission (or
`--at` SECONDS), and PNGs
of the recording's layout (`rerun_convert.blueprint`, which every mission.rrd carries).

    .venv/bin/python bench/screenshot_viewer.py RUN_DIR [--out DIR] [--prefix NAME]
    .venv/bin/python bench/screenshot_viewer.py runs/demo --out docs/figures --prefix viewer

Writes PREFIX_map3d.png (the 3D map, robots, trajectories, frontiers and goals, seen from
above the map: the camera is placed from merged_map.ply's bounds), PREFIX_grid2d.png (the
merged grid with frontiers and robots), PREFIX_coverage.png (the coverage curves), each with
its view maximized and the time panel hidden, and PREFIX_viewer.png (the whole viewer, the
time panel collapsed to its one line).

How: `rerun --headless --window-size WxH --port P` (no window, no X display) driven over
gRPC with `rerun.experimental.ViewerClient`: open the .rrd, poll until it has loaded and has
its `sim_time` range, read its blueprint and set it back with the camera or a maximized view,
put the cursor at the end, then capture the view until two captures `settle` seconds apart
are the same and not blank (the viewer fetches chunks on demand, so the first frames can
show "Loading…"); it fails after `--timeout` seconds rather than keep a half-loaded frame.

Requirements: rerun-sdk 0.41 or newer (the `rerun` viewer beside this interpreter, else on
PATH; `--headless` and `ViewerClient` are experimental and may change), Pillow, and a Vulkan
driver: a GPU's, or Mesa's software rasterizer lavapipe (Debian: `apt-get install
mesa-vulkan-drivers`; not in scripts/setup.sh, the tests do not need it). A recording made
before the layout was added (no blueprint in the file) is shot with rerun's automatic views.
"""

from __future__ import annotations

import argparse
import io
import logging
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from services.processes import free_tcp_port  # noqa: E402

log = logging.getLogger("screenshot_viewer")


class ScreenshotError(RuntimeError):
    """What stopped the screenshots, worded for the person running the script."""


@dataclass(frozen=True)
class Shot:
    """One PNG: `suffix` of the file name; the view picked by `match` (class, name, origin)
    over the viewer's views, or the whole viewer when `match` is None."""

    suffix: str
    match: Callable[[str, str, str], bool] | None


SHOTS = (
    Shot("map3d", lambda cls, name, origin: cls == "3D" and origin == "/world"),
    Shot("grid2d", lambda cls, name, origin: cls == "2D" and origin == "/grid"),
    Shot("coverage", lambda cls, name, origin: cls == "TimeSeries" and (
        name == "coverage (%)" or origin == "/plots/coverage_3d_pct")),
    Shot("viewer", None),
)


def rerun_executable() -> str:
    """The rerun viewer installed beside this interpreter, else PATH's."""
    beside = Path(sys.executable).parent / "rerun"
    found = str(beside) if beside.exists() else shutil.which("rerun")
    if found is None:
        raise ScreenshotError("no `rerun` viewer beside this interpreter or on PATH "
                              "(pip install rerun-sdk)")
    return found


def viewer_client_class() -> Any:
    try:
        from rerun.experimental import ViewerClient
    except ImportError as exc:
        raise ScreenshotError("this rerun-sdk has no rerun.experimental.ViewerClient "
                              "(needs 0.41 or newer)") from exc
    if not hasattr(ViewerClient, "take_screenshot"):
        raise ScreenshotError("this rerun-sdk's ViewerClient cannot take screenshots "
                              "(needs 0.41 or newer)")
    return ViewerClient


def until(what: str, deadline: float, probe: Callable[[], Any], every_s: float = 0.5) -> Any:
    """Call `probe` until it returns something truthy (returned) or `deadline` passes."""
    last_error: Exception | None = None
    while time.monotonic() < deadline:
        try:
            value = probe()
        except ScreenshotError:
            raise
        except Exception as exc:  # the viewer not up yet, a transient gRPC error
            last_error, value = exc, None
        if value:
            return value
        time.sleep(every_s)
    raise ScreenshotError(f"timed out waiting for {what}"
                          + (f" (last error: {last_error})" if last_error else ""))


def blank(png: bytes) -> bool:
    """Whether a capture is (nearly) one colour: nothing drawn in it."""
    from PIL import Image

    grey = np.asarray(Image.open(io.BytesIO(png)).convert("L"), dtype=np.float32)
    return grey.size == 0 or float(grey.std()) < 2.0


def stable_capture(client: Any, view_id: str | None, deadline: float,
                   settle_s: float = 1.5) -> bytes:
    """A capture of `view_id` (None: the whole viewer) equal to the one `settle_s` before
    it and not blank: everything the view needs has loaded and been drawn."""
    previous: bytes | None = None
    while time.monotonic() < deadline:
        png = client.take_screenshot(view_id)
        if png == previous and not blank(png):
            return png
        previous = png
        time.sleep(settle_s)
    raise ScreenshotError(f"view {view_id or '(whole viewer)'} did not settle before the "
                          "deadline (still loading, or blank)")


def map_bounds(run_dir: Path) -> tuple[np.ndarray, np.ndarray] | None:
    """(min, max) xyz of the run folder's merged map, None without one."""
    ply = run_dir / "merged_map.ply"
    if not ply.is_file():
        return None
    from services.evaluator.run_files import read_ply

    points = read_ply(ply)
    return (points.min(axis=0), points.max(axis=0)) if len(points) else None


def with_eye(blueprint: dict[str, Any], view_id: str,
             bounds: tuple[np.ndarray, np.ndarray]) -> dict[str, Any]:
    """`blueprint` (as `ViewerClient.get_blueprint` reads it) with the 3D view's camera
    above the map, south of it, looking down at its centre: the robots and trajectories
    inside the rooms show over the walls (rerun's automatic camera is level with them)."""
    lo, hi = bounds
    centre = (lo + hi) / 2.0
    span = float(max(hi[0] - lo[0], hi[1] - lo[1]))
    target = [float(centre[0]), float(centre[1]), 0.0]
    position = [float(centre[0]), float(centre[1] - 0.55 * span), float(1.05 * span)]
    out = dict(blueprint)
    out[f"/view/{view_id}/EyeControls3D"] = {"EyeControls3D": {
        "kind": "Orbital", "position": position, "look_target": target,
        "eye_up": [0.0, 0.0, 1.0]}}
    return out


def time_panel(blueprint: dict[str, Any], state: str) -> dict[str, Any]:
    """`blueprint` with the time panel `Expanded`, `Collapsed` (one line) or `Hidden`."""
    out = dict(blueprint)
    panel = dict(out.get("/time_panel", {}).get("TimePanelBlueprint", {}))
    panel["state"] = state
    out["/time_panel"] = {"TimePanelBlueprint": panel}
    return out


def maximized(blueprint: dict[str, Any], view_id: str) -> dict[str, Any]:
    """`blueprint` with `view_id` filling the viewport and the time panel hidden."""
    out = time_panel(blueprint, "Hidden")
    viewport = dict(out.get("/viewport", {}).get("ViewportBlueprint", {}))
    viewport["maximized"] = view_id
    out["/viewport"] = {"ViewportBlueprint": viewport}
    return out


def save_png(png: bytes, path: Path, max_kb: int) -> None:
    """Write `png`; above `max_kb`, as a 256-colour palette PNG (rerun's flat dark UI and
    the map's few colours survive it; the docs keep each figure under ~500 KB)."""
    if len(png) <= max_kb * 1024:
        path.write_bytes(png)
        return
    from PIL import Image

    image = Image.open(io.BytesIO(png)).convert("RGB")
    image.quantize(colors=256, method=Image.Quantize.FASTOCTREE).save(path, optimize=True)


def spawn_viewer(size: str, port: int, workdir: Path) -> subprocess.Popen[bytes]:
    cmd = [rerun_executable(), "--headless", "--window-size", size, "--port", str(port),
           "--hide-welcome-screen", "--memory-limit", "50%"]
    log.info("starting %s", " ".join(cmd))
    env = dict(os.environ, XDG_RUNTIME_DIR=str(workdir))  # wgpu's probe asks for one
    with open(workdir / "viewer.log", "wb") as out:
        # its own process group: a pip-installed `rerun` is a Python launcher that runs the
        # viewer binary as a child, which outlives a signal sent to the launcher alone
        return subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=env,
                                start_new_session=True)


def stop_viewer(proc: subprocess.Popen[bytes], grace_s: float = 10.0) -> None:
    """SIGTERM the viewer's process group (launcher and binary), SIGKILL what is left."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(timeout=grace_s)
        except subprocess.TimeoutExpired:
            continue
        deadline = time.monotonic() + grace_s
        while time.monotonic() < deadline:  # the binary may outlive the launcher briefly
            try:
                os.killpg(proc.pid, 0)
            except ProcessLookupError:
                return
            time.sleep(0.2)
    proc.poll()


def viewer_failure(proc: subprocess.Popen[bytes], workdir: Path) -> ScreenshotError:
    text = (workdir / "viewer.log").read_text(errors="replace")
    hint = ""
    if any(sign in text.lower() for sign in ("graphics adapter", "render context", "vulkan")):
        hint = (" — no usable graphics adapter: install a Vulkan driver "
                "(Debian: apt-get install mesa-vulkan-drivers)")
    return ScreenshotError(f"the rerun viewer exited with {proc.returncode}{hint}; its log:\n"
                           + text[-3000:])


def take_screenshots(run_dir: Path, out_dir: Path, prefix: str, size: str,
                     timeout_s: float, max_kb: int = 450,
                     at_s: float | None = None) -> list[Path]:
    """Write the PNGs of `SHOTS` for `run_dir`'s recording at sim time `at_s` (None: its
    end) into `out_dir`; return their paths."""
    rrd = run_dir / "mission.rrd"
    if not rrd.is_file():
        raise ScreenshotError(f"{rrd} not found: a run folder of `spacemap run` (with "
                              "record.rrd on, the default) holds one")
    client_class = viewer_client_class()
    out_dir.mkdir(parents=True, exist_ok=True)
    deadline = time.monotonic() + timeout_s
    with tempfile.TemporaryDirectory(prefix="spacemap_shots_") as tmp:
        workdir = Path(tmp)
        port = free_tcp_port()
        proc = spawn_viewer(size, port, workdir)
        try:
            url = f"rerun+http://127.0.0.1:{port}/proxy"

            def up() -> Any:  # the client connects when made: retry until the viewer listens
                if proc.poll() is not None:
                    raise viewer_failure(proc, workdir)
                client = client_class(url)
                client.get_state()
                return client

            client = until("the viewer to answer", deadline, up)
            client.open(str(rrd.resolve()))

            def loaded() -> Any:
                if proc.poll() is not None:
                    raise viewer_failure(proc, workdir)
                state = client.get_state()
                if state.loading or state.active_recording is None:
                    return None
                rec = next((r for r in state.recordings
                            if r.store_id == state.active_recording), None)
                sim = next((t for t in (rec.timelines if rec else [])
                            if t.name == "sim_time" and t.end is not None), None)
                return sim and (state, sim)

            state, sim = until(f"{rrd} to load", deadline, loaded)
            end_s = sim.end * 1e-9
            log.info("loaded %s: sim_time %.1f to %.1f s, %d views", rrd,
                     sim.start * 1e-9, end_s, len(state.views))
            when_s = end_s if at_s is None else min(max(at_s, 0.0), end_s)
            views = [(v.view_id, v.view_class, v.name, v.origin) for v in state.views]
            picked: dict[str, str | None] = {}
            for shot in SHOTS:
                picked[shot.suffix] = None if shot.match is None else next(
                    (vid for vid, cls, name, origin in views if shot.match(cls, name, origin)),
                    None)
                if shot.match is not None and picked[shot.suffix] is None:
                    raise ScreenshotError(f"no view for {shot.suffix} among {views}")
            store = state.active_recording
            layout = client.get_blueprint(store_id=store).blueprint
            bounds = map_bounds(run_dir)
            view3d = picked["map3d"]
            if bounds is not None and view3d is not None:
                layout = with_eye(layout, view3d, bounds)
            written = []
            for shot in SHOTS:
                view_id = picked[shot.suffix]
                client.set_blueprint(time_panel(layout, "Collapsed") if view_id is None
                                     else maximized(layout, view_id), store_id=store)
                client.set_time("sim_time", duration=when_s, play_state="paused")
                png = stable_capture(client, view_id, deadline)
                path = out_dir / f"{prefix}_{shot.suffix}.png"
                save_png(png, path, max_kb)
                log.info("wrote %s (%d KB)", path, path.stat().st_size // 1024)
                written.append(path)
            return written
        finally:
            stop_viewer(proc)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run_dir", type=Path, help="a run folder of `spacemap run`")
    parser.add_argument("--out", type=Path, default=None, help="default: RUN_DIR")
    parser.add_argument("--prefix", default="viewer", help="file name prefix")
    parser.add_argument("--size", default="1600x1000", help="viewer size, WxH points")
    parser.add_argument("--at", type=float, default=None,
                        help="sim time of the shots, s (default: the end of the recording)")
    parser.add_argument("--max-kb", type=int, default=450,
                        help="a PNG larger than this is saved with a 256-colour palette")
    parser.add_argument("--timeout", type=float, default=180.0,
                        help="seconds for the whole capture (software rendering is slow)")
    args = parser.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    try:
        take_screenshots(args.run_dir, args.out or args.run_dir, args.prefix, args.size,
                         args.timeout, args.max_kb, args.at)
    except ScreenshotError as exc:
        log.error("%s", exc)
        sys.exit(1)


if __name__ == "__main__":
    main()
