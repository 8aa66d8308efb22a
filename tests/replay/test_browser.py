"""Replays in Debian's headless Chromium (WebGL through SwiftShader, no GPU).

A tab opens the replay of a real run and shows a non-empty scene; moving the time slider changes
it; two tabs with two page URLs watch two runs at once, one of them comparing.
"""

from __future__ import annotations

import io
import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.replay.conftest import ServiceDb, free_port
from web.replay.app import ViewerHandle, start_viewer
from web.replay.session import ClientSession

CHROMIUM = Path("/usr/bin/chromium")
VIEWPORT = {"width": 960, "height": 640}
# The scene part of a screenshot: left of the GUI panel, below viser's notifications.
SCENE = (slice(170, 640), slice(0, 610))
# viser's own page parameter: render at half resolution, 4x less work for software WebGL.
LOW_DPR = "fixedDpr=0.5"
# 3.5 % of the scene part: far more than any stray pixel, far less than the area mesh covers.
MIN_DRAWN = 10_000
ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "replay"


@pytest.fixture(scope="module")
def browser(playwright_driver: Any) -> Iterator[Any]:
    if not CHROMIUM.is_file():
        message = f"{CHROMIUM} is missing (apt-get install chromium)"
        if os.environ.get("CI") == "true":
            pytest.fail(message + "; under CI=true it must be there")
        pytest.skip(message)
    browser = playwright_driver.chromium.launch(executable_path=str(CHROMIUM), args=[
        "--use-gl=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist"])
    yield browser
    browser.close()


def wait_for(condition: Callable[[], Any], what: str, timeout: float = 40.0) -> Any:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.25)
    raise AssertionError(f"timed out waiting for {what}")


def scene_pixels(page: Any) -> np.ndarray:
    """(H, W, 3) the scene part of a screenshot."""
    from PIL import Image  # ships with viser (through imageio)

    image = Image.open(io.BytesIO(page.screenshot())).convert("RGB")
    return np.asarray(image)[SCENE]


def drawn(pixels: np.ndarray) -> int:
    """Pixels that are not the white background."""
    return int(np.count_nonzero((pixels < 235).any(axis=2)))


def session_of(handle: ViewerHandle, key: str) -> ClientSession:
    def find() -> ClientSession | None:
        for session in list(handle.app.sessions.values()):
            if session.primary is not None and session.primary.run.key == key \
                    and session.update_seconds:
                return session
        return None

    found: ClientSession = wait_for(find, f"a tab showing {key}")
    return found


def stable_screenshot(page: Any, minimum: int) -> np.ndarray:
    """A screenshot once the scene has at least `minimum` drawn pixels and stopped changing."""
    last: list[np.ndarray] = []

    def settled() -> bool:
        pixels = scene_pixels(page)
        done = bool(last) and drawn(pixels) >= minimum and np.array_equal(pixels, last[-1])
        last.append(pixels)
        return done

    began = time.monotonic()
    wait_for(settled, "the scene to render")
    print("settled after", time.monotonic() - began, len(last))
    return last[-1]


def test_replay_shows_the_run_and_the_slider_changes_it(browser: Any, run_dir: Path,
                                                        tmp_path: Path) -> None:
    from server.settings import Settings

    handle = start_viewer(Settings(data_dir=tmp_path), "127.0.0.1", free_port(),
                          recording=run_dir / "recording.npz")
    page = browser.new_page(viewport=VIEWPORT)
    try:
        page.goto(f"{handle.url}/?{LOW_DPR}")
        session = session_of(handle, handle.app.default_key or "")
        start = stable_screenshot(page, minimum=MIN_DRAWN)  # the area mesh at least
        page.get_by_text("explored volume").first.wait_for()
        # Move the time slider to the end, as a user does with the keyboard.
        slider = page.get_by_role("slider").first
        slider.focus()
        page.keyboard.press("End")
        end_time = session.primary.run.duration if session.primary else 0.0
        wait_for(lambda: session.clock.time >= round(end_time, 1) - 1e-6, "the session at t end")
        end = stable_screenshot(page, minimum=MIN_DRAWN)
        changed = int(np.count_nonzero((np.abs(end.astype(int) - start.astype(int)) > 30)
                                       .any(axis=2)))
        ARTIFACTS.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "replay-end.png"))
        # The map, trajectory and final mesh of 20 s of flight cover a good part of the view.
        assert changed > 5_000, changed
        assert drawn(end) > drawn(start)
        # Update latency is measured by benchmarks/replay_load.py, not here: a loaded machine
        # slows a scene update by whole seconds without anything being wrong.
        assert session.update_seconds, "the session never updated its scene"
    finally:
        page.close()
        handle.stop()


def test_two_tabs_watch_two_runs_by_their_urls(browser: Any, service_db: ServiceDb) -> None:
    first, second = service_db.with_recording
    handle = start_viewer(service_db.settings, "127.0.0.1", free_port())
    tab_a = browser.new_page(viewport=VIEWPORT)
    tab_b = browser.new_page(viewport=VIEWPORT)
    try:
        tab_a.goto(f"{handle.url}/?run={first}&{LOW_DPR}")
        tab_b.goto(f"{handle.url}/?run={second}&compare={first}&{LOW_DPR}")
        a = session_of(handle, f"run:{first}")
        b = session_of(handle, f"run:{second}")
        assert a is not b and a.compare is None
        wait_for(lambda: b.compare is not None, "tab B to compare")
        assert b.compare is not None and b.compare.run.key == f"run:{first}"
        # Each tab shows its own run's title; tab B also the compared run, in column B.
        tab_a.get_by_text(f"run {first}: classic-v1 on maze").first.wait_for()
        assert tab_a.get_by_text(f"run {second}: classic-v1").count() == 0
        tab_b.get_by_text(f"run {second}: classic-v1 on maze").first.wait_for()
        tab_b.get_by_text(f"run {first}: classic-v1 on maze").first.wait_for()
        # The stored series (10 m³ per second) is what the panel shows at t = 0.
        tab_a.get_by_text("0.0 m³").first.wait_for()
        tab_a.close()  # the two software renderers share two cores
        assert drawn(stable_screenshot(tab_b, minimum=MIN_DRAWN)) >= MIN_DRAWN
    finally:
        tab_a.close()
        tab_b.close()
        handle.stop()
