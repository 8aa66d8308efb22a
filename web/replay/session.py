"""One browser tab: its GUI, its scene, its clock.

Every tab gets a `ClientSession` with one thread that owns the tab's scene: GUI callbacks (run on
viser's thread pool) only post commands to it, so scene updates never interleave, and a burst of
slider moves collapses into one update at the latest value.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from time import monotonic
from typing import Any, Protocol

import numpy as np

from web.replay.cache import RunCache
from web.replay.extras import default_clip_z
from web.replay.query import read_query
from web.replay.scene import Layers, RunScene
from web.replay.source import RunData, RunLookupError, Series

log = logging.getLogger(__name__)

PRIMARY_COLOUR = (30, 120, 220)
COMPARE_COLOUR = (245, 130, 30)
SPEEDS = ("1x", "5x", "10x", "30x", "60x")
DEFAULT_SPEED = "10x"
TICK_S = 0.2  # playback updates per second: 5
PLOT_POINTS = 400


class ReplayHost(Protocol):
    """What a session needs from the app."""

    cache: RunCache
    file_mode: bool

    def initial_keys(self, query: dict[str, str]) -> tuple[str | None, str | None]: ...

    def key_for(self, text: str) -> str: ...

    def recent_runs(self) -> list[tuple[int, str]]: ...


@dataclass
class _Clock:
    time: float = 0.0
    playing: bool = False
    speed: float = 10.0
    last_tick: float = field(default_factory=monotonic)


def metrics_markdown(t: float, runs: list[tuple[str, RunData, RunScene]]) -> str:
    """The metrics panel: one column per run."""
    head = "| t = {:.1f} s | {} |\n|---|{}\n".format(
        t, " | ".join(label for label, _, _ in runs), "---|" * len(runs))

    def row(name: str, cell: Callable[[RunData, RunScene], str]) -> str:
        return f"| {name} | " + " | ".join(cell(r, s) for _, r, s in runs) + " |\n"

    def recall(r: RunData, _s: RunScene) -> str:
        value = r.recall_at(t)
        return "-" if value is None else f"{value:.3f}"

    body = (row("explored volume", lambda r, _s: f"{r.volume_at(t):.1f} m³")
            + row("surface recall", recall)
            + row("path so far", lambda r, s: f"{path_length(r, s.pose_index(t)):.1f} m"))
    primary = runs[0][2]
    body += (f"| occupied voxels | {primary.counts['occupied']:,} |\n"
             f"| frontier voxels | {primary.counts['frontiers']:,} |\n")
    titles = "".join(f"- **{label}**: {r.title}\n" for label, r, _ in runs)
    return titles + "\n" + head + body


def path_length(run: RunData, pose_index: int) -> float:
    poses = run.recording.poses
    if pose_index < 1:
        return 0.0
    steps = np.diff(poses[: pose_index + 1, :3].astype(np.float64), axis=0)
    return float(np.linalg.norm(steps, axis=1).sum())


class ClientSession:
    """The replay in one tab."""

    def __init__(self, host: ReplayHost, client: Any) -> None:
        self.host, self.client = host, client
        self.layers = Layers()
        self.clock = _Clock()
        self.primary: RunScene | None = None
        self.compare: RunScene | None = None
        self._commands: queue.Queue[tuple[str, Any]] = queue.Queue()
        self._closed = threading.Event()
        self._thread = threading.Thread(target=self._main, daemon=True,
                                        name=f"replay-client-{client.client_id}")
        self.update_seconds: list[float] = []  # server time of each scene update (benchmark)
        self.first_frame_at: float | None = None
        self._markdown_text = ""
        self.gui: dict[str, Any] = {}

    def start(self) -> None:
        self._thread.start()

    def close(self) -> None:
        self._closed.set()
        self._commands.put(("close", None))

    def post(self, command: str, value: Any = None) -> None:
        self._commands.put((command, value))

    # -- the session thread --------------------------------------------------------------------
    def _main(self) -> None:
        try:
            self._build_gui()
            primary, compare = self.host.initial_keys(read_query(self.client))
            if primary is not None:
                self._open(primary)
                if compare is not None:
                    self._open_compare(compare)
            while not self._closed.is_set():
                try:
                    command, value = self._commands.get(timeout=TICK_S)
                except queue.Empty:
                    command, value = "tick", None
                self._handle(command, value)
                # Drain what piled up meanwhile: only the latest time matters.
                while not self._commands.empty():
                    self._handle(*self._commands.get_nowait())
                self._advance()
                self._render()
        except Exception:  # a tab that disconnects mid-update raises deep inside viser
            if not self._closed.is_set():
                log.exception("replay session of client %s failed", self.client.client_id)

    def _handle(self, command: str, value: Any) -> None:
        if command == "time":
            self.clock.time = float(value)
        elif command == "play":
            if self.primary is not None and self.clock.time >= self.primary.run.duration:
                self.clock.time = 0.0
            self.clock.playing = True
            self.clock.last_tick = time.monotonic()
        elif command == "pause":
            self.clock.playing = False
        elif command == "speed":
            self.clock.speed = float(str(value).rstrip("x"))
        elif command == "open":
            self._open(str(value))
        elif command == "compare":
            self._open_compare(str(value))
        elif command == "uncompare":
            self._drop_compare()

    def _advance(self) -> None:
        now = time.monotonic()
        if self.clock.playing and self.primary is not None:
            end = self.primary.run.duration
            step = self.clock.speed * (now - self.clock.last_tick)
            self.clock.time = min(end, self.clock.time + step)
            if self.clock.time >= end:
                self.clock.playing = False
            self.gui["time"].value = round(self.clock.time, 1)
        self.clock.last_tick = now

    def _render(self) -> None:
        if self.primary is None:
            return
        began = time.perf_counter()
        with self.client.atomic():
            self.primary.show(self.clock.time, self.layers)
            if self.compare is not None:
                self.compare.show(self.clock.time, self.layers)
        self._update_metrics()
        self.update_seconds.append(time.perf_counter() - began)
        if self.first_frame_at is None:
            self.first_frame_at = time.perf_counter()

    def _update_metrics(self) -> None:
        runs = [("A", self.primary.run, self.primary)] if self.primary else []
        if self.compare is not None:
            runs.append(("B", self.compare.run, self.compare))
        text = metrics_markdown(self.clock.time, runs)
        if text != self._markdown_text:
            self._markdown_text = text
            self.gui["metrics"].content = text

    # -- opening runs --------------------------------------------------------------------------
    def _load(self, key: str) -> RunData | None:
        note = self.client.add_notification("Loading", key.split(":", 1)[-1], loading=True,
                                            with_close_button=False)
        try:
            return self.host.cache.get(key)
        except RunLookupError as exc:
            self.client.add_notification("Cannot replay", str(exc), color="red",
                                         auto_close_seconds=10.0)
            return None
        except Exception as exc:  # a database or store failure: this tab carries on
            log.exception("loading %s failed", key)
            self.client.add_notification("Cannot replay", f"{key}: {exc}", color="red",
                                         auto_close_seconds=10.0)
            return None
        finally:
            note.remove()

    def _open(self, key: str) -> None:
        run = self._load(key)
        if run is None:
            return
        self._drop_compare()
        if self.primary is not None:
            self.primary.clear()
        self.primary = RunScene(self.client.scene, run, "/a", PRIMARY_COLOUR, primary=True,
                                extras=self.host.cache.extras(run))
        self.clock = _Clock(speed=self.clock.speed)
        slider = self.gui["time"]
        slider.max = max(round(run.duration, 1), 0.5)
        slider.value = 0.0
        self._reset_clip(run)
        self._aim_camera(run)
        self._update_plot()

    def _open_compare(self, key: str) -> None:
        if self.primary is None:
            return
        run = self._load(key)
        if run is None:
            return
        if run.area.name != self.primary.run.area.name:
            self.client.add_notification(
                "Cannot compare", f"{run.title} flew {run.area.name}, not "
                f"{self.primary.run.area.name}", color="red", auto_close_seconds=10.0)
            return
        self._drop_compare()
        self.compare = RunScene(self.client.scene, run, "/b", COMPARE_COLOUR, primary=False)
        self._update_plot()

    def _drop_compare(self) -> None:
        if self.compare is not None:
            self.compare.clear()
            self.compare = None
            self._update_plot()

    def _reset_clip(self, run: RunData) -> None:
        """Clip just under the top of the area: a ceiling would hide everything beneath it."""
        lo, hi = float(run.area.bounds_min[2]), float(run.area.bounds_max[2])
        default = default_clip_z(run)
        clip = self.gui["clip"]
        clip.min, clip.max = round(lo, 2), round(hi, 2)
        clip.value = round(default, 2)
        self.layers.clip_z = default

    def _aim_camera(self, run: RunData) -> None:
        lo, hi = run.area.bounds_min, run.area.bounds_max
        centre = (lo + hi) / 2.0
        size = float(np.max(hi - lo))
        camera = self.client.camera
        camera.up_direction = (0.0, 0.0, 1.0)
        camera.position = tuple(float(v) for v in centre + np.array([-0.3, -0.6, 1.0]) * size)
        camera.look_at = tuple(float(v) for v in centre)

    def _update_plot(self) -> None:
        old = self.gui.pop("plot", None)
        if old is not None:
            old.remove()
        if self.primary is None:
            return
        a = self.primary.run.volume
        # A few hundred points draw the curve as well as thousands, and keep the tab light.
        stride = max(1, len(a.times) // PLOT_POINTS)
        a = Series(a.times[::stride], a.values[::stride])
        series: list[dict[str, Any]] = [{"label": "t (s)"},
                                        {"label": "A (m³)", "stroke": "#1e78dc", "width": 2}]
        data = [a.times, a.values]
        if self.compare is not None:
            b = self.compare.run.volume
            data.append(np.interp(a.times, b.times, b.values, right=np.nan))
            series.append({"label": "B (m³)", "stroke": "#f5821e", "width": 2})
        with self.gui["plot_folder"]:
            self.gui["plot"] = self.client.gui.add_uplot(
                tuple(np.asarray(d, dtype=np.float64) for d in data), tuple(series),
                scales={"x": {"time": False}},  # seconds, not dates
                axes=({"label": "t (s)"}, {"label": "m³"}), aspect=1.6)

    # -- the GUI -------------------------------------------------------------------------------
    def _build_gui(self) -> None:
        gui = self.client.gui
        self.client.scene.set_up_direction("+z")
        # Shadow maps render the scene several more times per frame: too slow for the large
        # point clouds on a laptop, let alone software WebGL, and they add nothing here.
        self.client.scene.configure_default_lights(enabled=True, cast_shadow=False)
        # The default image-based lighting (an HDR environment map) is prefiltered in the
        # browser at start, for seconds in software WebGL, before anything is drawn. The default
        # lights alone light the flat-shaded meshes well enough.
        self.client.scene.configure_environment_map(None)
        with gui.add_folder("Timeline"):
            slider = gui.add_slider("t (s)", min=0.0, max=1.0, step=0.1, initial_value=0.0)
            slider.on_update(self._on_slider)
            self.gui["time"] = slider
            buttons = gui.add_button_group("Playback", ("Play", "Pause"))
            buttons.on_click(lambda e: self.post("play" if e.target.value == "Play" else "pause"))
            speed = gui.add_dropdown("Speed", SPEEDS, initial_value=DEFAULT_SPEED)
            speed.on_update(lambda _e: self.post("speed", speed.value))
        with gui.add_folder("Metrics"):
            self.gui["metrics"] = gui.add_markdown("Choose a run below.")
        self.gui["plot_folder"] = gui.add_folder("Explored volume")
        with gui.add_folder("Layers", expand_by_default=False):
            self._layer_gui()
        with gui.add_folder("Runs", expand_by_default=self.host.file_mode is False):
            self._runs_gui()

    def _layer_gui(self) -> None:
        gui = self.client.gui
        boxes = [("area_mesh", "Area mesh"), ("truth", "Ground-truth surface"),
                 ("occupied", "Occupied voxels"), ("frontiers", "Frontiers"),
                 ("trajectory", "Trajectory"), ("plan", "Planned path"),
                 ("surface", "Reconstructed surface"), ("final_mesh", "Final mesh (at the end)")]
        for attr, label in boxes:
            box = gui.add_checkbox(label, initial_value=bool(getattr(self.layers, attr)))
            box.on_update(lambda _e, a=attr, b=box: self._set_layer(a, bool(b.value)))
        opacity = gui.add_slider("Mesh opacity", min=0.0, max=1.0, step=0.05,
                                 initial_value=self.layers.area_opacity)
        opacity.on_update(lambda _e: self._set_layer("area_opacity", float(opacity.value)))
        clip = gui.add_slider("Clip map above z (m)", min=0.0, max=1.0, step=0.05,
                              initial_value=1.0)
        clip.on_update(lambda _e: self._set_layer("clip_z", float(clip.value)))
        self.gui["clip"] = clip
        gui.add_markdown("Final mesh colour: distance to the truth, green 0 → yellow 5 cm → "
                         "red ≥ 10 cm.")

    def _set_layer(self, attr: str, value: object) -> None:
        setattr(self.layers, attr, value)  # read by the session thread at its next update
        self.post("layers")

    def _runs_gui(self) -> None:
        gui = self.client.gui
        hint = "a recording path" if self.host.file_mode else "a run id"
        target = gui.add_text("Run", initial_value="", hint=f"{hint} to replay")
        gui.add_button("Open").on_click(lambda _e: self._post_key("open", target.value))
        if not self.host.file_mode:
            recent = self.host.recent_runs()
            if recent:
                labels = tuple(label for _, label in recent)
                pick = gui.add_dropdown("Recent", labels, initial_value=labels[0])
                ids = dict(zip(labels, (str(i) for i, _ in recent), strict=True))
                gui.add_button("Open recent").on_click(
                    lambda _e: self._post_key("open", ids[pick.value]))
        other = gui.add_text("Compare with", initial_value="", hint=f"{hint} on the same area")
        gui.add_button("Compare").on_click(lambda _e: self._post_key("compare", other.value))
        gui.add_button("Stop comparing").on_click(lambda _e: self.post("uncompare"))

    def _post_key(self, command: str, text: str) -> None:
        try:
            self.post(command, self.host.key_for(text))
        except RunLookupError as exc:
            self.client.add_notification("Cannot open", str(exc), color="red",
                                         auto_close_seconds=8.0)

    def _on_slider(self, event: Any) -> None:
        if event.client is None:  # set by playback (viser calls back for those too)
            return
        slider = self.gui["time"]
        value = float(slider.value)
        if self.primary is not None and value >= float(slider.max) - 1e-9:
            value = self.primary.run.duration  # the slider's last step is the end of the run
        self.post("pause")
        self.post("time", value)
