"""The website in Debian's headless Chromium, against `flybo serve` with results of real jobs.

Screenshots of every page at 1280 and 390 px go to test-artifacts/web/.
"""

from __future__ import annotations

from typing import Any

import pytest

from tests.web.conftest import ARTIFACTS, Service


def test_leaderboard_shows_the_planner(page: Any, service: Service) -> None:
    page.goto(service.base + "/")
    row = page.locator("#coverage-table tbody tr[data-planner='classic-v3']")
    assert row.count() == 1
    assert "baseline" in row.inner_text()
    board = service.get("/api/v1/leaderboard")
    entry = next(e for e in board["entries"] if e["planner"] == "classic-v3")
    mean, low, high = (entry["coverage"][k] * 100 for k in ("mean", "min", "max"))
    cell = row.locator("td").nth(2).inner_text()
    assert cell.startswith(f"{mean:.1f}") and f"{low:.1f}–{high:.1f}" in cell
    assert page.locator("#area-table tbody tr", has_text="classic-v3").count() == 1
    # Figure 4 holds one mean line (and band) per planner, 21 samples for 20 s runs.
    page.wait_for_function("() => document.getElementById('volume-chart').chart !== undefined")
    series = page.evaluate("document.getElementById('volume-chart').chart.data.length")
    assert series == 1 + 3 * len(service.planners)
    assert page.evaluate("document.getElementById('volume-chart').chart.data[0].length") == 21
    page.wait_for_function("() => document.getElementById('pareto-chart').chart !== undefined")


def test_sorting_reorders_the_leaderboard(page: Any, service: Service) -> None:
    if len(service.planners) < 2:
        pytest.skip("no second built-in planner has results: the leaderboard has one row")
    page.goto(service.base + "/")
    header = page.locator("#coverage-table thead th", has_text="Planner")
    header.locator("button").click()
    ascending = [r.split()[0] for r in _rows_text(page, 1)]
    assert ascending == sorted(ascending)
    assert header.get_attribute("aria-sort") == "ascending"
    header.locator("button").click()
    descending = [r.split()[0] for r in _rows_text(page, 1)]
    assert descending == sorted(ascending, reverse=True) and descending != ascending
    # A numeric column sorts by number: the mean coverage.
    page.locator("#coverage-table thead th", has_text="Average").locator("button").click()
    # A cell holds the mean, then its confidence interval on a line of its own.
    means = [float(t.split()[0]) for t in _rows_text(page, 3)]
    assert means == sorted(means)


def _rows_text(page: Any, column: int) -> list[str]:
    texts: list[str] = page.eval_on_selector_all(
        "#coverage-table tbody tr",
        f"rows => rows.map(r => r.cells[{column}].innerText.trim())")
    return texts


def test_sorting_the_runs_of_a_planner(page: Any, service: Service) -> None:
    page.goto(service.base + "/planners/classic")
    page.locator("#runs-table thead th", has_text="Seed").locator("button").click()
    column = "rows => rows.map(r => Number(r.cells[3].dataset.sort))"
    seeds = page.eval_on_selector_all("#runs-table tbody tr", column)
    assert seeds == sorted(seeds) and len(seeds) >= 2
    page.locator("#runs-table thead th", has_text="Seed").locator("button").click()
    again = page.eval_on_selector_all("#runs-table tbody tr", column)
    assert again == sorted(seeds, reverse=True) and again != seeds


def test_run_page_draws_its_curves(page: Any, service: Service,
                                   console_errors: list[str]) -> None:
    run_id = service.jobs[0]["runs"][0]["id"]
    series = service.get(f"/api/v1/runs/{run_id}/series")
    page.goto(f"{service.base}/runs/{run_id}")
    page.wait_for_function("() => document.getElementById('volume-chart').chart !== undefined")
    drawn = page.evaluate("document.getElementById('volume-chart').chart.data")
    assert drawn[0] == series["time_s"]
    assert drawn[1] == pytest.approx(series["explored_volume_m3"])
    assert page.get_attribute("#volume-chart", "data-points") == str(len(series["time_s"]))
    assert page.locator("#volume-chart canvas").count() == 1
    recall = page.evaluate("document.getElementById('recall-chart').chart.data[1]")
    assert recall == pytest.approx([v * 100 for v in series["surface_recall"]])
    assert page.get_attribute("a:has-text('Open 3D replay')", "href") == f"/runs/{run_id}/replay"
    mesh = page.get_attribute("a:has-text('Final mesh')", "href")
    assert mesh == f"/api/v1/runs/{run_id}/artifacts/mesh"
    # The log: refused without the owner's token, shown with it, the token kept if asked.
    page.click("text=Show log")
    page.wait_for_function("() => document.getElementById('log').textContent.startsWith('Refused')")
    assert page.inner_text("#log").startswith("Refused (401)")
    console_errors.remove("Failed to load resource: the server responded with a status of 401 "
                          "(Unauthorized)")
    page.fill("#token", service.token)
    page.check("#remember")
    page.click("text=Show log")
    page.wait_for_function(
        f"() => document.getElementById('log').textContent.includes('run {run_id} succeeded')")
    assert page.evaluate("localStorage.getItem('flybo-token')") == service.token


def test_job_page_progress_advances(page: Any, service: Service) -> None:
    # In preset exact, so that the default leaderboard the other tests read stays as it was.
    job = service.submit("classic", 1, 100, preset="exact")
    page.goto(f"{service.base}/jobs/{job['id']}")
    page.evaluate("window.notReloaded = true")
    start = page.evaluate("document.querySelector('#job-progress progress').value")
    assert start < 1
    # Advances while the job runs, updated in place by polling (the page is not reloaded).
    page.wait_for_function(
        f"() => {{ const v = document.querySelector('#job-progress progress').value;"
        f" return v > {start} && v < 1; }}", timeout=90_000)
    assert page.inner_text("#job-status") == "running"
    page.wait_for_function("() => document.getElementById('job').dataset.final === '1'",
                           timeout=120_000)
    assert page.inner_text("#job-status") == "succeeded"
    assert page.evaluate("document.querySelector('#job-progress progress').value") == 1
    assert page.evaluate("window.notReloaded") is True
    service.wait(job["id"])


@pytest.mark.parametrize("width", [1280, 390])
def test_screenshots_of_every_page(browser: Any, service: Service, width: int) -> None:
    run_id = service.jobs[0]["runs"][0]["id"]
    pages = {"leaderboard": "/", "areas": "/areas", "planners": "/planners",
             "planner": "/planners/classic", "jobs": "/jobs",
             "job": f"/jobs/{service.jobs[0]['id']}", "run": f"/runs/{run_id}"}
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    context = browser.new_context(viewport={"width": width, "height": 900})
    tab = context.new_page()
    errors: list[str] = []
    tab.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    tab.on("pageerror", lambda e: errors.append(str(e)))
    try:
        for name, path in pages.items():
            tab.goto(service.base + path)
            tab.wait_for_load_state("networkidle")
            # Usable at this width: the page itself never scrolls sideways (wide tables
            # scroll inside their own box).
            overflow = tab.evaluate(
                "document.documentElement.scrollWidth - document.documentElement.clientWidth")
            assert overflow <= 1, (name, width, overflow)
            if name == "areas":
                tab.locator("#area-maze img").scroll_into_view_if_needed()
                tab.wait_for_function(
                    "() => document.querySelector('#area-maze img').naturalWidth > 0",
                    timeout=60_000)
            tab.screenshot(path=str(ARTIFACTS / f"{name}-{width}.png"), full_page=True)
    finally:
        context.close()
    assert not errors, errors
    assert (ARTIFACTS / f"run-{width}.png").stat().st_size > 10_000
