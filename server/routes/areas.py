"""Areas: the built-in scenes and uploaded building models."""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Annotated, Literal

from fastapi import APIRouter, File, Form, HTTPException, Request, UploadFile
from sqlalchemy import select
from sqlalchemy.exc import IntegrityError

from server.catalog import CatalogError, ensure_area, upsert_area
from server.deps import OptionalUserDep, SessionDep, SettingsDep, UserDep
from server.heldout import NAME_PREFIX
from server.mesh_guard import MeshGuardError, prescan
from server.models import PUBLIC_SPLIT, AreaRow
from server.schemas import AreaOut
from server.split_access import refuse_hidden, sees_heldout
from server.storage import ArtifactStoreError, settings_store

router = APIRouter(prefix="/areas", tags=["areas"])

AREA_FILE_KEY = "areas/{name}.npz"
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf", ".dae")


def area_out(row: AreaRow) -> AreaOut:
    return AreaOut(name=row.name, builtin=row.builtin, title=str(row.stats.get("title", row.name)),
                   content_hash=row.content_hash, plateau_s=row.plateau_s,
                   voxel_size=row.voxel_size,
                   stats={k: v for k, v in row.stats.items() if k != "file"},
                   split=row.split, heldout_generation=row.heldout_generation)


@router.get("", response_model=list[AreaOut])
def list_areas(session: SessionDep, user: OptionalUserDep) -> list[AreaOut]:
    """Every area; the held-out ones for admins only (`server.split_access`)."""
    query = select(AreaRow).order_by(AreaRow.name)
    if not sees_heldout(user):
        query = query.where(AreaRow.split == PUBLIC_SPLIT)
    return [area_out(r) for r in session.scalars(query)]


@router.get("/{name}", response_model=AreaOut, responses={404: {"description": "no such area"}})
def get_area(name: str, session: SessionDep, request: Request,
             user: OptionalUserDep) -> AreaOut:
    row = session.scalar(select(AreaRow).where(AreaRow.name == name))
    if row is not None:
        refuse_hidden(row, user)
        return area_out(row)
    # First sight of a built-in area: its row is written, by a writing session.
    with request.app.state.sessions() as writer:
        try:
            row = ensure_area(writer, name)
        except CatalogError as exc:
            raise HTTPException(404, str(exc)) from None
        writer.commit()
        return area_out(row)


@router.post("", response_model=AreaOut, status_code=201,
             responses={409: {"description": "name taken"}, 413: {"description": "too large"},
                        422: {"description": "not a usable mesh"}})
def upload_area(
    request: Request,
    session: SessionDep,
    settings: SettingsDep,
    user: UserDep,
    file: Annotated[UploadFile, File(description="OBJ, PLY, STL, OFF, GLB/GLTF or DAE mesh")],
    name: Annotated[str, Form(pattern=r"^[a-z0-9][a-z0-9-]{0,39}$",
                              description="lower-case letters, digits, hyphens")],
    scale: Annotated[float, Form(gt=0, le=1000, allow_inf_nan=False,
                                 description="metres per file unit")] = 1.0,
    up: Annotated[Literal["x", "y", "z", "-x", "-y", "-z"], Form()] = "z",
) -> AreaOut:
    # The simulation stack (Open3D), loaded by the API when an area is first uploaded.
    from areas.importer import ImportLimits, MeshImportError, import_mesh
    from areas.registry import area_names
    from areas.store import AreaStoreError, save_area

    limit = settings.max_area_upload_bytes
    length = request.headers.get("content-length")
    if length is not None and length.isdigit() and int(length) > limit + 64 * 1024:
        raise HTTPException(413, f"upload too large: at most {settings.max_area_upload_mib:g} MiB")
    suffix = Path(file.filename or "").suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise HTTPException(422, f"unsupported mesh file type {suffix or '(none)'!r}; use one "
                                 f"of {', '.join(MESH_SUFFIXES)}")
    if name.startswith(NAME_PREFIX):  # the held-out areas' names
        raise HTTPException(422, f"names starting with {NAME_PREFIX!r} are reserved")
    if name in area_names() or session.scalar(select(AreaRow.id).where(AreaRow.name == name)):
        raise HTTPException(409, f"an area named {name!r} already exists")
    with tempfile.TemporaryDirectory(prefix="flybo-upload-") as tmp:
        path = Path(tmp) / f"mesh{suffix}"
        size = 0
        with path.open("wb") as out:
            while block := file.file.read(1 << 20):
                size += len(block)
                if size > limit:
                    raise HTTPException(413, f"upload too large: at most "
                                             f"{settings.max_area_upload_mib:g} MiB")
                out.write(block)
        limits = ImportLimits(max_file_bytes=limit)
        try:
            prescan(path, limits.max_faces)
        except MeshGuardError as exc:
            raise HTTPException(422, f"mesh rejected: {exc}") from None
        try:
            area = import_mesh(path, name, scale=scale, up=up, limits=limits)
        except MeshImportError as exc:
            raise HTTPException(422, f"mesh rejected: {exc}") from None
        try:
            saved = save_area(area, folder=settings.areas_dir)
        except AreaStoreError as exc:
            raise HTTPException(409, str(exc)) from None
        try:
            stored = settings_store(settings).put(AREA_FILE_KEY.format(name=name), saved)
        except ArtifactStoreError as exc:
            saved.unlink(missing_ok=True)
            raise HTTPException(503, f"could not store the area: {exc}") from None
    try:
        row = upsert_area(session, area, builtin=False, owner_id=user.id)
        row.stats = {**row.stats, "file": stored.location}
        session.commit()
    except IntegrityError:
        session.rollback()
        raise HTTPException(409, f"an area named {name!r} already exists") from None
    return area_out(row)
