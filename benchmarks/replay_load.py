"""Replay of a long run: time to the first frame, slider update time, recording size.

    .venv/bin/python benchmarks/replay_load.py --area maze --seconds 1800
    .venv/bin/python benchmarks/replay_load.py --recording RUN/recording.npz   # an existing run

Without --recording, the run is made first with `flybo run` (Classic, preset default) into
`/tmp/flybo-bench-replay/<area>-<seconds>` and reused on the next call.

Server side, as the viewer does it for a new tab: read the recording, load the area, replay the
keyframes (`MapTimeline`), draw the first scene (`RunScene.show` at t = 0) into a viser server;
then slider moves to seeded random times and to the end, each
timed as the handler's time (`show`). In the browser (Debian's Chromium, software WebGL): time
from opening the page to a drawn scene. Targets: first frame < 3 s, slider update < 200 ms,
recording <= 50 MB per 1800 s.
"""

from __future__ import annotations

import argparse
import io
import socket
import subprocess
import sys
import tempfile
import time
import zipfile
from concurrent.futures import Future
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import peak_rss_mib, print_table, write_json

CHROMIUM = Path("/usr/bin/chromium")
WORK = Path(tempfile.gettempdir()) / "flybo-bench-replay"


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def make_run(area: str, seconds: float) -> Path:
    from flybo.cli import main

    out = WORK / f"{area}-{seconds:g}"
    if not (out / "recording.npz").is_file():
        WORK.mkdir(parents=True, exist_ok=True)
        main(["run", "--area", area, "--planner", "classic", "--seconds", f"{seconds:g}",
              "--preset", "default", "--out", str(out), "--quiet"])
    return out / "recording.npz"


def recording_sizes(path: Path, duration: float) -> dict[str, Any]:
    """Compressed bytes per array, the total, and the total per 1800 s.

    Surface snapshots each hold the whole surface so far, so they grow faster than linearly
    with the run; the extrapolation counts every snapshot of an 1800 s run at the size of the
    last one of this run (an upper bound once the surface stops growing), the rest linearly.
    """
    with zipfile.ZipFile(path) as archive:
        sizes = {i.filename.removesuffix(".npy"): i.compress_size for i in archive.infolist()}
    total = path.stat().st_size
    data = np.load(path)
    offsets, times = data["surface_offsets"], data["surface_times"]
    surface = sum(v for k, v in sizes.items() if k.startswith("surface_"))
    rest = total - surface
    if len(times) and offsets[-1] > 0:
        per_point = sizes["surface_points"] / offsets[-1]
        last = int(offsets[-1] - offsets[-2])
        interval = float(times[1] - times[0]) if len(times) > 1 else max(duration, 1.0)
        surface_1800 = per_point * last * (1800.0 / interval)
    else:
        surface_1800 = 0.0
    scale = 1800.0 / max(duration, 1e-9)
    per_1800 = total if duration >= 1799.0 else int(rest * scale + max(surface_1800,
                                                                       surface * scale))
    return {"arrays": sizes, "total_bytes": total, "per_1800_s_bytes": per_1800,
            "per_1800_s_measured": duration >= 1799.0}


def import_seconds() -> float:
    """Importing the viewer in a fresh interpreter (Open3D through `areas`): once per viewer
    process, before any tab."""
    code = ("import time; t = time.perf_counter(); import viser, web.replay.app, "
            "web.replay.scene; print(time.perf_counter() - t)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=Path(__file__).resolve().parents[1])
    return float(out.stdout.strip().splitlines()[-1])


def server_side(path: Path, moves: int, seed: int) -> dict[str, Any]:
    """First frame and slider moves, timed as the viewer's handlers run them."""
    import viser

    from web.replay.extras import Extras, compute_extras
    from web.replay.scene import Layers, RunScene
    from web.replay.source import load_file_run
    from web.replay.timeline import MapTimeline

    imports = import_seconds()

    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    try:
        t0 = time.perf_counter()
        run = load_file_run(path)
        t1 = time.perf_counter()
        scene = RunScene(server.scene, run, "/a", (30, 120, 220), primary=True)
        layers = Layers(clip_z=float(run.area.bounds_max[2]) - 1.5 * run.timeline.voxel_size)
        scene.show(0.0, layers)
        t2 = time.perf_counter()
        # The pieces of the load, measured again on their own (the area is memoised now).
        from sim.recording import Recording

        r0 = time.perf_counter()
        recording = Recording(path)
        r1 = time.perf_counter()
        MapTimeline(recording)
        r2 = time.perf_counter()
        rng = np.random.default_rng(seed)
        targets = [*rng.uniform(0.0, run.duration, size=moves).tolist(), run.duration]
        updates = []
        for t in targets:
            s = time.perf_counter()
            scene.show(float(t), layers)
            updates.append(time.perf_counter() - s)
        # The background work of a new run, then the end of the timeline with the final mesh.
        e0 = time.perf_counter()
        extras: Future[Extras] = Future()
        extras.set_result(compute_extras(run))
        extras_s = time.perf_counter() - e0
        scene.extras = extras
        scene.show(0.0, layers)
        e1 = time.perf_counter()
        scene.show(run.duration, layers)
        final_mesh_s = time.perf_counter() - e1
        final = extras.result().final_mesh
    finally:
        server.stop()
    moves_s = np.asarray(updates[:-1])
    return {
        "duration_s": run.duration, "area": run.area.name,
        "grid_shape": list(run.timeline.shape), "keyframes": len(run.timeline.times),
        "checkpoint_every": run.timeline.checkpoint_every,
        "imports_s": imports, "load_s": t1 - t0, "read_recording_s": r1 - r0,
        "replay_keyframes_s": r2 - r1, "first_scene_s": t2 - t1, "first_frame_s": t2 - t0,
        "slider_median_s": float(np.median(moves_s)), "slider_p95_s": float(
            np.percentile(moves_s, 95)), "slider_max_s": float(moves_s.max()),
        "slider_to_end_s": updates[-1], "moves": moves,
        "occupied_at_end": scene.counts["occupied"], "frontiers_at_end": scene.counts["frontiers"],
        "extras_s": extras_s, "slider_to_end_with_final_mesh_s": final_mesh_s,
        "final_mesh_faces": None if final is None else [final.source_faces, len(final.faces)],
    }


def browser_side(path: Path) -> dict[str, Any] | None:
    """Seconds from opening the page to a drawn scene, in software-rendered WebGL."""
    if not CHROMIUM.is_file():
        return None
    from PIL import Image
    from playwright.sync_api import sync_playwright

    from server.settings import Settings
    from web.replay.app import start_viewer

    handle = start_viewer(Settings(data_dir=WORK / "data"), "127.0.0.1", free_port(),
                          recording=path)
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), args=[
                "--use-gl=swiftshader", "--enable-unsafe-swiftshader",
                "--ignore-gpu-blocklist"])
            page = browser.new_page(viewport={"width": 960, "height": 640})
            began = time.perf_counter()
            page.goto(f"{handle.url}/?fixedDpr=0.5")
            shown = None
            while time.perf_counter() - began < 60.0:
                image = np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB"))
                if np.count_nonzero((image[170:, :610] < 235).any(axis=2)) > 10_000:
                    shown = time.perf_counter() - began
                    break
            sessions = list(handle.app.sessions.values())
            browser.close()
    finally:
        handle.stop()
    first = sessions[0].first_frame_at if sessions else None
    return {"page_to_drawn_scene_s": shown,
            "page_to_first_scene_sent_s": None if first is None else first - began}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--area", default="maze")
    parser.add_argument("--seconds", type=float, default=1800.0)
    parser.add_argument("--recording", type=Path, default=None)
    parser.add_argument("--moves", type=int, default=40)
    parser.add_argument("--no-browser", action="store_true")
    args = parser.parse_args()
    path = args.recording or make_run(args.area, args.seconds)
    server = server_side(path, args.moves, seed=0)
    sizes = recording_sizes(path, server["duration_s"])
    browser = None if args.no_browser else browser_side(path)
    mib = 1 << 20
    rows = [
        ["run", f"{server['area']}, {server['duration_s']:.0f} s, grid "
                f"{'x'.join(map(str, server['grid_shape']))}", ""],
        ["imports (once per viewer process)", f"{server['imports_s']:.2f} s", ""],
        ["read recording", f"{server['read_recording_s']:.2f} s", ""],
        ["replay keyframes (checkpoints)", f"{server['replay_keyframes_s']:.2f} s",
         f"{server['keyframes']} keyframes, every {server['checkpoint_every']}"],
        ["load (recording + area + keyframes)", f"{server['load_s']:.2f} s", ""],
        ["first scene", f"{server['first_scene_s'] * 1000:.0f} ms", ""],
        ["**first frame, server**", f"{server['first_frame_s']:.2f} s", "target < 3 s"],
        ["slider move, median / p95 / max",
         f"{server['slider_median_s'] * 1000:.0f} / {server['slider_p95_s'] * 1000:.0f} / "
         f"{server['slider_max_s'] * 1000:.0f} ms", "target < 200 ms"],
        ["slider to the end", f"{server['slider_to_end_s'] * 1000:.0f} ms",
         f"{server['occupied_at_end']:,} occupied, {server['frontiers_at_end']:,} frontier"],
        ["background: truth tree, coloured final mesh", f"{server['extras_s']:.2f} s",
         "after the first frame"],
        ["slider to the end, with the final mesh",
         f"{server['slider_to_end_with_final_mesh_s'] * 1000:.0f} ms",
         "faces shown / full: " + ("-" if server["final_mesh_faces"] is None else
                                   "{1:,} / {0:,}".format(*server["final_mesh_faces"]))],
        ["recording", f"{sizes['total_bytes'] / mib:.1f} MiB", ""],
        ["recording per 1800 s", f"{sizes['per_1800_s_bytes'] / mib:.1f} MiB",
         "target <= 50 MB; " + ("measured" if sizes["per_1800_s_measured"] else
                                "extrapolated (upper bound)")],
    ]
    if browser is not None and None not in browser.values():
        rows.append(["page open to first scene sent (server)",
                     f"{browser['page_to_first_scene_sent_s']:.2f} s", "page load, websocket, URL"])
        rows.append(["page open to drawn scene (Chromium, software WebGL)",
                     f"{browser['page_to_drawn_scene_s']:.2f} s", "no GPU on this machine"])
    rows.append(["peak resident memory", f"{peak_rss_mib():.0f} MiB", ""])
    print_table("Replay load", ["quantity", "value", "note"], rows)
    out = write_json("replay_load", {"recording": str(path), "server": server, "sizes": sizes,
                                     "browser": browser, "peak_rss_mib": peak_rss_mib()})
    print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
