"""The page shell and small HTML helpers shared by every page.

Pages are f-strings: every value that comes from the database or the request goes through
`esc` (or a helper that calls it). Scripts are files under `/static/js/`, never inline, so the
Content-Security-Policy can forbid inline scripts; they read what they need from `data-*`
attributes.
"""

from __future__ import annotations

from collections.abc import Iterable
from html import escape
from typing import Any

from fastapi.responses import HTMLResponse

from server.schemas import Spread

CSP = ("default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
       "connect-src 'self'; object-src 'none'; base-uri 'none'; form-action 'self'; "
       "frame-ancestors 'none'")
HEADERS = {"Content-Security-Policy": CSP, "X-Content-Type-Options": "nosniff",
           "Referrer-Policy": "same-origin"}
NAV = (("/", "Leaderboard"), ("/areas", "Areas"), ("/planners", "Planners"), ("/jobs", "Jobs"),
       ("/docs", "API"))
DASH = "–"


def esc(value: Any) -> str:
    """Text for HTML content or a quoted attribute value."""
    return escape(str(value), quote=True)


def page(title: str, body: str, *, scripts: Iterable[str] = (), status: int = 200,
         charts: bool = False, current: str = "") -> HTMLResponse:
    """A whole page; `scripts` are file names under /static/js/, `charts` loads uPlot."""
    # An empty icon: browsers stop asking for /favicon.ico.
    head = ["<link rel='icon' href='data:,'><link rel='stylesheet' href='/static/site.css'>"]
    tags = []
    if charts:
        head.append("<link rel='stylesheet' href='/static/vendor/uplot/uPlot.min.css'>")
        tags.append("<script src='/static/vendor/uplot/uPlot.iife.min.js' defer></script>")
        tags.append("<script src='/static/js/charts.js' defer></script>")
    tags += [f"<script src='/static/js/{esc(name)}' defer></script>" for name in scripts]
    here = " aria-current='page'"
    nav = "".join(f"<li><a href='{href}'{here if href == current else ''}>{label}</a></li>"
                  for href, label in NAV)
    html = (
        "<!doctype html><html lang='en'><head><meta charset='utf-8'>"
        "<meta name='viewport' content='width=device-width, initial-scale=1'>"
        f"<title>{esc(title)} · FLYBO</title>{''.join(head)}{''.join(tags)}</head><body>"
        "<header class='top'><a class='brand' href='/'>FLYBO</a>"
        f"<nav aria-label='Main'><ul>{nav}</ul></nav></header>"
        f"<main id='main'>{body}</main>"
        "<footer><p>FLYBO: a benchmark for exploration planners of flying robots. "
        "Data: <a href='/docs'>REST API</a>.</p></footer></body></html>")
    return HTMLResponse(html, status_code=status, headers=HEADERS)


def not_found(what: str) -> HTMLResponse:
    return page("Not found", f"<h1>Not found</h1><p>{esc(what)}</p>"
                "<p><a href='/'>Back to the leaderboard</a></p>", status=404)


def num(value: float | None, digits: int = 2, scale: float = 1.0) -> str:
    return DASH if value is None else f"{value * scale:.{digits}f}"


def sort_key(value: float | str | None) -> str:
    """The `data-sort` attribute: numbers sort numerically, missing values go last."""
    if value is None:
        return ""
    return esc(f"{value:.9g}" if isinstance(value, float | int) else value)


def td(text: str, sort: float | str | None = None, cls: str = "") -> str:
    """A cell; `text` is HTML already escaped by the caller."""
    attrs = f" data-sort='{sort_key(sort)}'" if sort is not None or text == DASH else ""
    if cls:
        attrs += f" class='{cls}'"
    return f"<td{attrs}>{text}</td>"


CI_TITLE = "95 % confidence interval of the mean (percentile bootstrap over runs)"


def ci_span(low: float | None, high: float | None, digits: int, scale: float = 1.0) -> str:
    """A 95 % interval shown after a mean, or nothing when there is none (a single run)."""
    if low is None or high is None:
        return ""
    return (f"<span class='ci' title='{CI_TITLE}'>[{num(low, digits, scale)}, "
            f"{num(high, digits, scale)}]</span>")


def spread_td(s: Spread, digits: int = 2, scale: float = 1.0) -> str:
    """Mean over runs, its 95 % interval, and the range from the smallest to the largest run."""
    if s.mean is None:
        return td(DASH, None)
    rng = ""
    if s.min is not None and s.max is not None and s.max != s.min:
        rng = (f"<span class='range'>{num(s.min, digits, scale)}{DASH}"
               f"{num(s.max, digits, scale)}</span>")
    ci = ci_span(s.ci_low, s.ci_high, digits, scale)
    return td(f"{num(s.mean, digits, scale)}{ci}{rng}", s.mean, "num")


def table(caption: str, headers: list[tuple[str, str]], rows: list[str], *,
          sortable: bool = True, empty: str = "Nothing yet.", table_id: str = "") -> str:
    """A table in a horizontally scrolling box; `headers` are (label, tooltip) pairs.

    In a sortable table each header is a button (keyboard reachable); `sort.js` reorders the
    rows by the cells' `data-sort` values.
    """
    def th(label: str, tip: str) -> str:
        title = f" title='{esc(tip)}'" if tip else ""
        inner = f"<button type='button'{title}>{label}</button>" if sortable else label
        return f"<th scope='col'{'' if sortable else title}>{inner}</th>"

    body = "".join(rows) or f"<tr><td colspan='{len(headers)}'>{esc(empty)}</td></tr>"
    ident = f" id='{esc(table_id)}'" if table_id else ""
    cls = " class='sortable'" if sortable and rows else ""
    return (f"<div class='scroll' role='region' aria-label='{esc(caption)}' tabindex='0'>"
            f"<table{ident}{cls}><caption>{esc(caption)}</caption><thead><tr>"
            f"{''.join(th(label, tip) for label, tip in headers)}</tr></thead>"
            f"<tbody>{body}</tbody></table></div>")


_METHOD_BADGES = {
    "original": "<span class='badge badge-original' title='the method as its paper published "
                "it: the row to set beside the paper&#39;s'>original method</span>",
    "variant": "<span class='badge badge-variant' title='differs from the method its paper "
               "published (docs/planners.md)'>variant</span>",
}


def planner_link(key: str, builtin: bool, method: str = "") -> str:
    """A planner's name linking to its page, with a badge for a built-in planner and one for
    what it is to its paper's method (`planners.fidelity`), where stated."""
    badge = " <span class='badge' title='built-in planner'>baseline</span>" if builtin else ""
    if method in _METHOD_BADGES:
        badge += " " + _METHOD_BADGES[method]
    return f"<a href='/planners/{esc(key)}'>{esc(key)}</a>{badge}"


def status_badge(status: str) -> str:
    return f"<span class='status status-{esc(status)}' data-status>{esc(status)}</span>"


def options(values: Iterable[str], selected: str | None) -> str:
    return "".join(f"<option value='{esc(v)}'{' selected' if v == selected else ''}>"
                   f"{esc(v)}</option>" for v in values)
