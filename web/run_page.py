"""Run pages: facts, what made the run (its reproducibility record), final metrics, curves,
downloads, the log tail (owner only), the replay link.

The curves are drawn by `run.js` from `/api/v1/runs/{id}/series`. The log needs the owner's
token: the page keeps it in the browser's localStorage and sends it only to this site's API.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, HTTPException
from fastapi.responses import HTMLResponse

from server.deps import SessionDep
from server.models import HELDOUT_SPLIT, RunState
from server.routes.runs import read_run
from server.schemas import ResultOut, RunOut
from web.html import DASH, esc, not_found, num, page, planner_link, status_badge
from web.jobs_page import progress_bar

router = APIRouter(include_in_schema=False)


# Metrics of the measures the rows above show already.
SHOWN_METRICS = frozenset({"coverage", "fscore", "precision", "recall", "rmse_m", "collisions",
                           "path_length_m", "iterations"})


def _other_metrics(r: ResultOut) -> list[tuple[str, str]]:
    """The rest of the run's metrics block, labelled as the measures label them."""
    if not r.metrics:
        return []
    from sim.measures import metric_infos  # the simulation stack, on use

    infos = {m.key: m for m in metric_infos()}
    rows = []
    for key, value in r.metrics.items():
        if key in SHOWN_METRICS:
            continue
        info = infos.get(key)
        label = f"{info.label}, {info.unit}" if info and info.unit else (info.label if info
                                                                          else key)
        if value is None:
            text = DASH
        elif info is not None and info.fmt == "d":
            text = str(int(value))
        else:
            text = format(value, info.fmt if info else ".4g")
        rows.append((label[:1].upper() + label[1:], text))
    return rows


def _metrics(r: ResultOut) -> str:
    rows = [
        ("Outcome", f"{r.outcome} ({r.reason})"),
        ("Simulated until, s", num(r.simulated_until_s, 1)),
        ("Explored volume, m³", num(r.explored_volume_m3, 1)),
        ("Volume at the plateau, m³", num(r.volume_at_plateau_m3, 1)),
        ("Observable volume, m³", num(r.observable_volume_m3, 1)),
        ("Coverage, %", num(r.coverage, 2, 100)),
        ("Volumetric efficiency, m³/s", num(r.volumetric_efficiency, 3)),
        ("Precision, %", num(r.precision, 2, 100)),
        ("Recall, %", num(r.recall, 2, 100)),
        ("F-score, %", num(r.fscore, 2, 100)),
        ("RMSE, cm", num(r.rmse_m, 2, 100)),
        ("Collisions", str(r.collisions)),
        ("Path length, m", num(r.path_length_m, 1)),
        ("Iterations", str(r.iterations)),
        ("Planning time median / mean / max, ms",
         f"{num(r.planning_ms_median, 1)} / {num(r.planning_ms_mean, 1)} / "
         f"{num(r.planning_ms_max, 1)}"),
        ("Wall time, s", num(r.wall_seconds, 1)),
        *_other_metrics(r),
    ]
    body = "".join(f"<tr><th scope='row'>{esc(k)}</th><td>{esc(v)}</td></tr>" for k, v in rows)
    return (f"<div class='scroll'><table class='stats' id='metrics'><caption>Final metrics"
            f"</caption><tbody>{body}</tbody></table></div>")


def _short(digest: Any) -> str:
    """A hash as its first 12 digits, the whole of it in the tooltip."""
    if not isinstance(digest, str) or not digest:
        return DASH
    return f"<code title='{esc(digest)}'>{esc(digest[:12])}</code>"


def _get(record: dict[str, Any], *keys: str) -> Any:
    value: Any = record
    for key in keys:
        value = value.get(key) if isinstance(value, dict) else None
    return value


def _record(r: ResultOut) -> str:
    """The reproducibility record: the benchmark version, code, preset, area, planner, seed,
    libraries and machine, and what could not be recorded."""
    head = f"<dt>Benchmark version</dt><dd><code id='run-benchmark-version'>" \
           f"{esc(r.benchmark_version)}</code></dd>"
    record = r.record
    if record is None:
        return (f"<dl class='facts' id='record'>{head}</dl><p>Stored before runs kept their "
                "reproducibility record.</p>")
    git = _get(record, "code", "git")
    commit = _short(_get(git or {}, "commit"))
    if isinstance(git, dict) and git.get("dirty"):
        commit += " <small>with uncommitted changes</small>"
    libraries = record.get("libraries")
    libs = (", ".join(f"{k} {v if v is not None else DASH}" for k, v in libraries.items())
            if isinstance(libraries, dict) else DASH)
    cores = _get(record, "machine", "cores")
    cpu = esc(_get(record, "machine", "cpu_model") or DASH) + (
        f" <small>{esc(cores)} cores</small>" if cores else "")
    speed = _get(record, "machine", "speed_factor")
    missing = record.get("missing") or []
    rows = [
        ("Code", f"{commit} <small>package {esc(_get(record, 'code', 'package_version') or DASH)}"
                 f", sources {_short(_get(record, 'code', 'sources_sha256'))}</small>"),
        ("Preset", f"{esc(_get(record, 'preset', 'name') or DASH)} "
                   f"{_short(_get(record, 'preset', 'sha256'))}"),
        ("Area", f"{esc(_get(record, 'area', 'name') or DASH)} "
                 f"{_short(_get(record, 'area', 'sha256'))}"
                 + (f" <small>{esc(g)}</small>" if (g := _get(record, 'area', 'generator'))
                    else "")),
        ("Planner", f"{esc(_get(record, 'planner', 'id') or DASH)} <small>code</small> "
                    f"{_short(_get(record, 'planner', 'code_sha256'))} <small>config</small> "
                    f"{_short(_get(record, 'planner', 'config_sha256'))}"),
        ("Seed", esc(record.get("seed", DASH))),
        ("Libraries", esc(libs)),
        ("CPU", cpu),
        ("Speed factor", num(speed, 3) if isinstance(speed, int | float) else DASH),
        ("Not recorded", "<ul class='missing'>" + "".join(
            f"<li>{esc(m)}</li>" for m in missing) + "</ul>" if missing else "nothing"),
    ]
    return (f"<dl class='facts' id='record'>{head}"
            + "".join(f"<dt>{k}</dt><dd>{v}</dd>" for k, v in rows) + "</dl>")


def _facts(run: RunOut) -> str:
    when = run.finished_at or run.started_at
    rows = [
        ("Job", f"<a href='/jobs/{run.job_id}'>job {run.job_id}</a>"),
        ("Planner", planner_link(run.planner, False)),
        ("Area", esc(run.area) if run.split == HELDOUT_SPLIT else
         f"<a href='/areas#area-{esc(run.area)}'>{esc(run.area)}</a>"),
        ("Seed", str(run.seed)), ("Preset", esc(run.preset)),
        ("Simulated seconds", num(run.seconds, 0)),
        ("Status", f"<span id='run-status'>{status_badge(run.status)}</span>"),
        ("Progress", f"<span id='run-progress'>{progress_bar(run.progress, 'run')}</span>"),
        ("Attempts", str(run.attempts)), ("Worker", esc(run.worker or DASH)),
        ("Wall time, s", num(run.wall_time_s, 1)),
        ("Finished" if run.finished_at else "Started",
         esc(when.strftime("%Y-%m-%d %H:%M:%S UTC")) if when else DASH),
    ]
    if run.error:
        rows.append(("Error", f"{esc(run.error)} ({esc(run.failure_kind or 'unknown')})"))
    return "<dl class='facts'>" + "".join(f"<dt>{k}</dt><dd>{v}</dd>" for k, v in rows) + "</dl>"


def _size(n: int) -> str:
    return f"{n / 1e6:.2f} MB" if n >= 100_000 else f"{n / 1e3:.1f} kB"


def _downloads(run: RunOut) -> str:
    names = {"mesh": "Final mesh (PLY)", "recording": "Recording (NPZ)",
             "result": "Result (JSON)"}
    items = "".join(
        f"<li><a href='{esc(a.url)}' download>{esc(names.get(a.kind, a.kind))}</a> "
        f"<small>{_size(a.size_bytes)}, SHA-256 <code>{esc(a.sha256[:12])}…</code>"
        "</small></li>" for a in run.artifacts)
    return f"<ul class='downloads'>{items}</ul>" if items else "<p>No files yet.</p>"


def _log_form(run_id: int) -> str:
    return (
        "<form class='controls' id='log-form'>"
        "<label for='token'>API token</label>"
        "<input id='token' name='token' type='password' autocomplete='off' "
        "placeholder='flybo_…' spellcheck='false'>"
        "<label><input type='checkbox' id='remember'> remember in this browser</label>"
        "<button type='submit'>Show log</button></form>"
        f"<pre id='log' class='log' tabindex='0' data-run='{run_id}' aria-live='polite'>"
        "Only the run's owner or an admin may read its log: enter your token.</pre>")


@router.get("/runs/{run_id}", response_class=HTMLResponse)
def run_page(run_id: str, session: SessionDep) -> HTMLResponse:
    if not run_id.isdigit() or len(run_id) >= 12:
        return not_found(f"No run with id {run_id}.")
    try:
        run = read_run(session, int(run_id), None)  # the website is anonymous
    except HTTPException:
        return not_found(f"No run with id {run_id}.")
    final = RunState(run.status).final
    charts = (
        f"<div class='figures' id='run-charts' data-run='{run.id}' "
        f"data-final='{'1' if final else '0'}'>"
        "<figure><div class='chart' id='volume-chart' role='img' aria-label='Explored volume "
        "over time'></div><figcaption>Explored volume over time, m³.</figcaption></figure>"
        "<figure><div class='chart' id='recall-chart' role='img' aria-label='Surface recall "
        "over time'></div><figcaption>Surface recall over time.</figcaption></figure></div>"
        "<p class='live' id='chart-note' aria-live='polite'></p>")
    heldout = run.split == HELDOUT_SPLIT
    replay = (f"<p class='lead'>A held-out run (generation {run.heldout_generation}): its "
              "metrics are public, its scene, files and log are not.</p>" if heldout else
              f"<p><a class='button' href='/runs/{run.id}/replay'>Open 3D replay</a></p>")
    body = (
        f"<h1>Run {run.id} <small>{esc(run.planner)} on {esc(run.area)}, seed {run.seed}"
        "</small></h1>"
        f"{replay}"
        f"{_facts(run)}"
        f"<h2>Curves</h2>{charts}"
        f"<h2>Metrics</h2>{_metrics(run.result) if run.result else '<p>Not finished.</p>'}"
        f"<h2>Reproducibility</h2>"
        f"{_record(run.result) if run.result else '<p>Not finished.</p>'}"
        f"<h2>Downloads</h2>"
        f"{'<p>Held-out runs publish no files.</p>' if heldout else _downloads(run)}"
        f"<h2>Log</h2>{_log_form(run.id)}")
    return page(f"Run {run.id}", body, scripts=("run.js",), charts=True, current="/jobs")
