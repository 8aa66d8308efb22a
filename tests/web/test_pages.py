"""Every page through the app, without a browser: status codes, escaping, security headers,
the tables' numbers, and the curves and Pareto set the figures are drawn from."""

from __future__ import annotations

import re

import pytest

from tests.web.conftest import Site
from tests.web.stored import HOSTILE, current_version


def _html(site: Site, path: str, status: int = 200) -> str:
    response = site.client.get(path)
    assert response.status_code == status, (path, response.text[:300])
    assert response.headers["content-type"].startswith("text/html")
    csp = response.headers["content-security-policy"]
    assert "script-src 'self'" in csp and "unsafe-inline" not in csp
    text = response.text
    # No inline script, style or event handler: the policy would block them.
    assert not re.search(r"<script(?![^>]*\ssrc=)[^>]*>", text), path
    assert not re.search(r"<[^>]+\s(on\w+|style)=", text), path
    assert "<style" not in text
    assert HOSTILE not in text and "<b>evil</b>" not in text, path
    return text


def test_every_page_answers(site: Site) -> None:
    run = site.ids["alpha_run"]
    for path in ["/", "/?preset=default&area=maze", "/?preset=exact", "/?preset=nothing-here",
                 "/?benchmark_version=legacy", f"/runs/{site.ids['legacy_run']}",
                 "/areas", "/planners", "/planners/alpha", "/planners/beta-v1", "/jobs",
                 "/jobs?offset=50", f"/jobs/{site.ids['alpha_job']}", f"/runs/{run}",
                 f"/runs/{site.ids['evil_run']}"]:
        _html(site, path)
    for path in ["/planners/teleport", "/jobs/99999", "/jobs/abc", "/jobs/1e3", "/runs/0",
                 "/?benchmark_version=1999.01-1",
                 "/runs/x", "/runs/99999999999999999999", "/areas/atlantis/thumbnail.png"]:
        assert "Not found" in _html(site, path, 404)
    assert site.client.get("/static/vendor/uplot/uPlot.iife.min.js").status_code == 200
    assert site.client.get("/static/js/charts.js").status_code == 200
    assert site.client.get("/static/nothing.js").status_code == 404


def test_hostile_strings_are_escaped(site: Site) -> None:
    escaped = "&lt;script&gt;alert(&#x27;x&#x27;)&lt;/script&gt;"
    assert escaped in _html(site, "/planners/beta")
    assert "&lt;b&gt;evil&lt;/b&gt;-v1" in _html(site, "/?preset=exact")
    assert escaped in _html(site, "/areas")
    assert "&lt;b&gt;evil&lt;/b&gt;-v1" in _html(site, f"/runs/{site.ids['evil_run']}")
    # A hostile query value is shown escaped (or not at all).
    assert "<x>" not in _html(site, "/?preset=%3Cx%3E&area=%3Cx%3E")


def test_leaderboard_tables(site: Site) -> None:
    text = _html(site, "/?area=maze")
    coverage = text[text.index("id='coverage-table'"):text.index("id='surface-table'")]
    # Overall order by coverage rank on the one scored area: beta 0.9, alpha 0.7, gamma 0.5;
    # the failed run of alpha (0.99) counts nowhere.
    order = re.findall(r"data-planner='([^']+)'", coverage)
    assert order == ["beta-v1", "alpha-v1", "gamma-v1"]
    alpha_row = coverage[coverage.index("data-planner='alpha-v1'"):]
    alpha_row = alpha_row[:alpha_row.index("</tr>")]
    # The mean, its bootstrap interval (two runs: resampled means of 60, 70 or 80 %), min-max.
    assert (">70.0<span class='ci' title='95 % confidence interval of the mean (percentile "
            "bootstrap over runs)'>[60.0, 80.0]</span><span class='range'>60.0–80.0</span>"
            in alpha_row)
    # Figure 6's error bars ride along: alpha is second in every resample.
    assert "data-coverage-rank-low='2' data-coverage-rank-high='2'" in alpha_row
    assert "baseline" in alpha_row
    # What each planner is to its paper: alpha the original method, gamma a variant; beta,
    # uploaded, says nothing.
    assert ">original method</span>" in alpha_row and ">variant<" not in alpha_row
    gamma_row = coverage[coverage.index("data-planner='gamma-v1'"):]
    assert ">variant</span>" in gamma_row[:gamma_row.index("</tr>")]
    beta_row = coverage[coverage.index("data-planner='beta-v1'"):]
    beta_row = beta_row[:beta_row.index("</tr>")]
    assert "baseline" not in beta_row  # uploaded, not built in
    assert "original method" not in beta_row and ">variant<" not in beta_row
    # Pareto: beta leads coverage, alpha leads F-score; gamma is beaten by both.
    assert re.search(r"data-planner='alpha-v1'[^>]*data-pareto='1'", coverage)
    assert re.search(r"data-planner='gamma-v1'[^>]*data-pareto='0'", coverage)
    table4 = text[text.index("id='area-table'"):]
    assert "Table 4: planning on maze" in table4 and "alpha-v1" in table4
    assert "id='volume-chart'" in text and "data-area='maze'" in text
    assert "No results yet." in _html(site, "/?preset=nothing-here")
    assert f"href='/jobs/{site.ids['alpha_job']}'" in text  # recent jobs


def test_leaderboard_api_marks_the_pareto_set(site: Site) -> None:
    board = site.client.get("/api/v1/leaderboard", params={"area": "maze"}).json()
    pareto = {p["planner"]: p["pareto"] for p in board["overall"]}
    assert pareto == {"alpha-v1": True, "beta-v1": True, "gamma-v1": False}
    alpha = next(p for p in board["overall"] if p["planner"] == "alpha-v1")
    assert alpha["mean_rmse_m"] == pytest.approx(0.02)


def test_curves_aggregate_runs_of_different_lengths(site: Site) -> None:
    body = site.client.get("/api/v1/curves", params={"area": "maze"}).json()
    assert body["area"] == "maze" and body["plateau_s"] == 700
    by = {p["planner"]: p for p in body["planners"]}
    assert set(by) == {"alpha-v1", "beta-v1", "gamma-v1"}
    alpha = by["alpha-v1"]
    assert alpha["runs"] == 2 and alpha["builtin"]  # the failed run is not there
    assert by["gamma-v1"]["runs"] == 1  # its legacy run is another version's
    assert body["benchmark_version"] == current_version()
    legacy = site.client.get("/api/v1/curves", params={"area": "maze",
                                                       "benchmark_version": "legacy"}).json()
    assert [(p["planner"], p["runs"]) for p in legacy["planners"]] == [("gamma-v1", 1)]
    assert alpha["time_s"] == [0, 1, 2, 3, 4]
    volume = alpha["explored_volume_m3"]
    # Runs [0,1,2,3,4] and [0,2,4]: both up to 2 s, then only the longer one.
    assert volume["mean"] == [0, 1.5, 3, 3, 4]
    assert volume["min"] == [0, 1, 2, 3, 4]
    assert volume["max"] == [0, 2, 4, 3, 4]
    assert alpha["recall_time_s"] == [20, 40]
    assert alpha["surface_recall"]["mean"] == pytest.approx([0.15, 0.3])
    thin = site.client.get("/api/v1/curves", params={"area": "maze", "max_points": 10}).json()
    assert len(thin["planners"][0]["time_s"]) <= 10
    assert site.client.get("/api/v1/curves", params={"area": "atlantis"}).status_code == 404
    empty = site.client.get("/api/v1/curves", params={"area": "maze", "preset": "fast"})
    assert empty.json()["planners"] == []


def test_run_page(site: Site) -> None:
    run = site.ids["alpha_run"]
    text = _html(site, f"/runs/{run}")
    assert f"href='/runs/{run}/replay'" in text and "Open 3D replay" in text
    assert f"href='/api/v1/runs/{run}/artifacts/mesh'" in text
    assert "F-score, %" in text and "50.00" in text
    assert "<label for='token'>API token</label>" in text
    assert "line one" not in text  # the log is only fetched with the owner's token
    log = site.client.get(f"/api/v1/runs/{run}/log",
                          headers={"Authorization": f"Bearer {site.token}"})
    assert log.status_code == 200 and "line one" in log.text


def test_job_planner_and_areas_pages(site: Site) -> None:
    job = _html(site, f"/jobs/{site.ids['alpha_job']}")
    assert "data-final='1'" in job and job.count("<tr data-run=") == 3
    assert "<progress max='1' value='1.0000'" in job
    planner = _html(site, "/planners/alpha")
    assert "&quot;step_m&quot;: 1.0" in planner  # the config, as JSON
    assert "alpha-v1" in planner and "id='runs-table'" in planner
    assert "<dt>Method</dt><dd>original: the method as its paper published it</dd>" in planner
    beta = _html(site, "/planners/beta")
    assert "<dd>alice</dd>" in beta  # the owner
    assert "<dt>Method</dt><dd>not stated</dd>" in beta
    # The planners list marks each built-in by its method.
    listing = _html(site, "/planners")
    assert ">original method</span>" in listing and ">variant</span>" in listing
    areas = _html(site, "/areas")
    assert "src='/areas/maze/thumbnail.png'" in areas and "20 × 20 × 2.5" in areas
    jobs = _html(site, "/jobs")
    assert f"href='/jobs/{site.ids['alpha_job']}'" in jobs


def test_the_leaderboard_shows_one_benchmark_version(site: Site) -> None:
    """The default page ranks the current version's results; the selector links to each
    version, and the legacy page ranks the legacy run alone."""
    current = current_version()
    text = _html(site, "/?area=maze")
    assert f"<code id='benchmark-version'>{current}</code> (current)" in text
    nav = text[text.index("id='benchmark-versions'"):text.index("</nav>",
                                                                text.index("id='benchmark-versions'"))]
    links = re.findall(r"<a href='([^']+)'( aria-current='page')?>([^<]+)</a>", nav)
    assert [(name, bool(here)) for _, here, name in links] == [(current, True), ("legacy", False)]
    assert all("benchmark_version=" in href and "preset=default" in href for href, _, _ in links)
    assert "4 runs, current" in nav and "1 run" in nav
    # Gamma's legacy run (coverage 0.95) would lead the table if versions were mixed.
    coverage = text[text.index("id='coverage-table'"):text.index("id='surface-table'")]
    assert re.findall(r"data-planner='([^']+)'", coverage) == ["beta-v1", "alpha-v1", "gamma-v1"]
    assert f"data-benchmark-version='{current}'" in text  # the curves of the same version

    legacy = _html(site, "/?benchmark_version=legacy&area=maze")
    assert "<code id='benchmark-version'>legacy</code>." in legacy
    coverage = legacy[legacy.index("id='coverage-table'"):legacy.index("id='surface-table'")]
    assert re.findall(r"data-planner='([^']+)'", coverage) == ["gamma-v1"]
    assert ">95.0<" in coverage
    # The form keeps the version it shows when the preset or area changes.
    assert "<input type='hidden' name='benchmark_version' value='legacy'>" in legacy
    assert "name='benchmark_version'" not in text
    assert "data-benchmark-version='legacy'" in legacy
    missing = _html(site, "/?benchmark_version=1999.01-1", 404)
    assert "1999.01-1" in missing and "legacy" in missing and current in missing


def test_the_leaderboard_shows_the_time_to_90_coverage(site: Site) -> None:
    """A leaderboard metric of the measures that the paper's columns do not show gets columns
    of its own: in Table 2 (mean over areas) and Table 4 (over runs)."""
    text = _html(site, "/?area=maze")
    coverage = text[text.index("id='coverage-table'"):text.index("id='surface-table'")]
    assert "time to 90 %, s" in coverage
    gamma = coverage[coverage.index("data-planner='gamma-v1'"):]
    gamma = gamma[:gamma.index("</tr>")]
    assert gamma.endswith("<td data-sort='30' class='num'>30</td>")
    alpha = coverage[coverage.index("data-planner='alpha-v1'"):]
    assert alpha[:alpha.index("</tr>")].endswith("<td data-sort='' class='num'>–</td>")
    table4 = text[text.index("id='area-table'"):]
    assert "time to 90 %, s" in table4
    board = site.client.get("/api/v1/leaderboard").json()
    gamma_entry = next(e for e in board["entries"] if e["planner"] == "gamma-v1")
    assert gamma_entry["metrics"]["time_to_90_coverage_s"]["mean"] == 30.0


def test_the_run_page_shows_the_record(site: Site) -> None:
    run = site.client.get(f"/api/v1/runs/{site.ids['alpha_run']}").json()
    result = run["result"]
    assert result["benchmark_version"] == current_version()
    assert result["record"]["seed"] == 0 and result["metrics"]["coverage"] == 0.8
    text = _html(site, f"/runs/{site.ids['alpha_run']}")
    record = text[text.index("id='record'"):text.index("</dl>", text.index("id='record'"))]
    assert f"<code id='run-benchmark-version'>{current_version()}</code>" in record
    for label in ("Code", "Preset", "Area", "Planner", "Seed", "Libraries", "CPU",
                  "Speed factor", "Not recorded"):
        assert f"<dt>{label}</dt>" in record, label
    legacy = _html(site, f"/runs/{site.ids['legacy_run']}")
    assert "<code id='run-benchmark-version'>legacy</code>" in legacy
    assert "Stored before runs kept their reproducibility record." in legacy
    assert site.client.get(f"/api/v1/runs/{site.ids['legacy_run']}").json()["result"][
        "record"] is None
