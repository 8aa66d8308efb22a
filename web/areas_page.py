"""The areas gallery (the paper's Table 1) and the areas' thumbnail images.

Thumbnails come from `areas.thumbnail`, which renders them once into the area cache; this
process renders a missing one on first request (under a lock, so a gallery of eleven images
does not ray-cast eleven meshes at once) and serves the file afterwards.
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path
from typing import Any, Literal

from fastapi import APIRouter
from fastapi.responses import FileResponse, HTMLResponse, Response
from sqlalchemy import select

from server.deps import SessionDep, SettingsDep
from server.models import PUBLIC_SPLIT, AreaRow
from server.routes.areas import area_out
from server.schemas import AreaOut
from web.html import DASH, esc, not_found, page, table, td

router = APIRouter(include_in_schema=False)
_render_lock = threading.Lock()
log = logging.getLogger(__name__)

# Statistics shown with a label and unit; any other key in `stats` is shown as it is.
LABELS: dict[str, str] = {
    "rooms": "Rooms", "levels": "Levels", "complexity": "Complexity", "indoor": "Indoor",
    "bounding_volume_m": "Bounding box, m", "faces": "Triangles",
}
HIDDEN = {"title", "start", "file"}


def _value(value: Any) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, list):
        return " × ".join(_value(v) for v in value)
    if isinstance(value, float):
        return f"{value:.6g}"
    if value is None:
        return DASH
    return str(value)


def _card(area: AreaOut) -> str:
    stats = [(LABELS.get(k, k.replace("_", " ")), v) for k, v in area.stats.items()
             if k not in HIDDEN]
    stats += [("Plateau time, s", area.plateau_s), ("Voxel, m", area.voxel_size)]
    rows = "".join(f"<tr><th scope='row'>{esc(label)}</th><td>{esc(_value(v))}</td></tr>"
                   for label, v in stats)
    name = esc(area.name)
    return (
        f"<article class='card' id='area-{name}'><h2>{esc(area.title)} <small>({name})</small>"
        f"{'' if area.builtin else ' <span class=badge>uploaded</span>'}</h2>"
        f"<img src='/areas/{name}/thumbnail.png' alt='{esc(area.title)} seen from above' "
        "width='320' height='240' loading='lazy' class='thumb'>"
        f"<table class='stats'><caption class='sr-only'>Statistics of {name}</caption>"
        f"<tbody>{rows}</tbody></table>"
        f"<p><a href='/?area={name}'>Results on {name}</a> · "
        f"<a href='/areas/{name}/thumbnail.png?view=perspective'>Perspective view</a> · "
        f"<a href='/api/v1/areas/{name}'>JSON</a></p></article>")


def _table1(areas: list[AreaOut]) -> str:
    """The paper's Table 1: one row per area, as `flybo report` writes it."""
    headers = [("Area", ""), ("Title", ""), ("Bounding box, m", "x × y × z of the mesh"),
               ("Rooms", ""), ("Levels", ""), ("Triangles", "faces of the mesh"),
               ("Complexity", ""), ("Indoor / outdoor", ""),
               ("Plateau time, s", "how long each run lasts"), ("Voxel, m", "")]
    rows = []
    for a in areas:
        box = a.stats.get("bounding_volume_m")
        # Sorted by the box's volume.
        volume = (float(box[0] * box[1] * box[2]) if isinstance(box, list) and len(box) == 3
                  else None)
        indoor = a.stats.get("indoor")
        cells = [
            td(f"<a href='#area-{esc(a.name)}'>{esc(a.name)}</a>", a.name),
            td(esc(a.title), a.title),
            td(esc(_value(box)), volume, "num"),
            _num_td(a.stats.get("rooms")), _num_td(a.stats.get("levels")),
            _num_td(a.stats.get("faces")),
            td(esc(_value(a.stats.get("complexity"))), str(a.stats.get("complexity") or "")),
            td(DASH if indoor is None else ("indoor" if indoor else "outdoor")),
            _num_td(a.plateau_s), _num_td(a.voxel_size)]
        rows.append(f"<tr>{''.join(cells)}</tr>")
    return table("Table 1: statistics of the areas", headers, rows, table_id="areas-table",
                 empty="No areas are registered yet.")


def _num_td(value: Any) -> str:
    number = value if isinstance(value, int | float) and not isinstance(value, bool) else None
    return td(esc(_value(value)), number, "num")


@router.get("/areas", response_class=HTMLResponse)
def areas_page(session: SessionDep) -> HTMLResponse:
    # The website is anonymous: the held-out areas are never listed (`server.split_access`).
    rows = [area_out(r) for r in session.scalars(
        select(AreaRow).where(AreaRow.split == PUBLIC_SPLIT).order_by(AreaRow.name))]
    cards = "".join(_card(a) for a in rows) or "<p>No areas are registered yet.</p>"
    body = ("<h1>Areas</h1><p class='lead'>The simulated scenes planners are tested in, with "
            f"their statistics (the paper's Table 1). {len(rows)} areas.</p>"
            f"{_table1(rows)}<div class='gallery'>{cards}</div>")
    return page("Areas", body, scripts=("sort.js",), current="/areas")


def _thumbnail(name: str, view: Literal["top", "perspective"], areas_dir: Path) -> Path | None:
    """The image of a built-in area, or of one stored in `areas_dir` (`Settings.areas_dir`)."""
    try:
        from areas.registry import area_names, load_area
        from areas.store import load_stored_area, stored_area_names
        from areas.thumbnail import thumbnail_paths, write_thumbnails
    except ImportError:  # an installation without the thumbnail renderer
        return None
    try:
        if name not in area_names() and name in stored_area_names(areas_dir):
            area = load_stored_area(name, areas_dir)
        else:
            area = load_area(name)
    except Exception:  # an unknown or unreadable area has no image; the page says so
        return None
    top, perspective = thumbnail_paths(area)
    path = top if view == "top" else perspective
    if not path.exists():
        with _render_lock:
            if not path.exists():
                try:
                    write_thumbnails(area)
                except Exception:  # logged; the gallery shows the statistics without it
                    log.exception("rendering the thumbnails of %s failed", name)
                    return None
    return path


@router.get("/areas/{name}/thumbnail.png", response_model=None)
def thumbnail(name: str, session: SessionDep, settings: SettingsDep,
              view: Literal["top", "perspective"] = "top") -> Response:
    if session.scalar(select(AreaRow.id).where(AreaRow.name == name,
                                               AreaRow.split == PUBLIC_SPLIT)) is None:
        return not_found(f"No area named {name}.")
    path = _thumbnail(name, view, settings.areas_dir)
    if path is None or not path.exists():
        return not_found(f"No thumbnail of {name}.")
    return FileResponse(path, media_type="image/png",
                        headers={"Cache-Control": "public, max-age=3600",
                                 "X-Content-Type-Options": "nosniff"})

