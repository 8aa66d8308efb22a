"""Planners: built-in ones and, later, uploaded ones, each with its versions."""

from __future__ import annotations

import logging
import tempfile
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, File, Form, HTTPException, Request, UploadFile
from sqlalchemy import func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from server.catalog import CatalogError, find_planner
from server.deps import SessionDep, SettingsDep, UserDep
from server.models import PlannerRow, User
from server.planner_package import (
    CHECKS_RETRY_AFTER_S,
    CheckOutcome,
    ChecksBusyError,
    CheckSlots,
    CheckUnavailableError,
    PackageError,
    PackageLimits,
    PlannerCheck,
    PlannerPackage,
    load_package,
)
from server.schemas import PlannerOut
from server.storage import ArtifactStoreError, settings_store

log = logging.getLogger(__name__)


router = APIRouter(prefix="/planners", tags=["planners"])


def planner_out(row: PlannerRow, owner: str | None, *, for_owner: bool = False) -> PlannerOut:
    # Where the code is stored is the service's business; the dry run's output is its owner's.
    config = {k: v for k, v in row.config.items() if k != "code"}
    if "check" in config and not for_owner:
        config["check"] = {k: v for k, v in config["check"].items() if k != "output"}
    return PlannerOut(name=row.name, version=row.version, id=row.key, builtin=row.builtin,
                      description=row.description, reference=row.reference,
                      method=row.method, config=config,
                      owner=owner, code_hash=row.code_hash or None)


@router.get("", response_model=list[PlannerOut])
def list_planners(session: SessionDep) -> list[PlannerOut]:
    rows = session.execute(
        select(PlannerRow, User.name).outerjoin(User, PlannerRow.owner_id == User.id)
        .order_by(PlannerRow.name, PlannerRow.version)
    )
    return [planner_out(row, owner) for row, owner in rows]


@router.get("/{name}", response_model=PlannerOut,
            responses={404: {"description": "no such planner"}})
def get_planner(name: str, session: SessionDep) -> PlannerOut:
    try:
        row = find_planner(session, name)
    except CatalogError as exc:
        raise HTTPException(404, str(exc)) from None
    owner = session.get(User, row.owner_id) if row.owner_id is not None else None
    return planner_out(row, owner.name if owner else None)


@router.post("", response_model=PlannerOut, status_code=201,
             responses={403: {"description": "the name belongs to another user"},
                        409: {"description": "a built-in planner's name"},
                        413: {"description": "too large"},
                        422: {"description": "refused by the checks or the dry run"},
                        429: {"description": "as many uploads as allowed are being checked"},
                        503: {"description": "no planner sandbox, or the store is away"}})
def upload_planner(
    request: Request,
    session: SessionDep,
    settings: SettingsDep,
    user: UserDep,
    file: Annotated[UploadFile, File(description="planner.py, or a .zip with planner.py")],
    name: Annotated[str, Form(pattern=r"^[a-z][a-z0-9-]{0,39}$",
                              description="lower-case letters, digits, hyphens")],
    description: Annotated[str, Form(max_length=2000)] = "",
) -> PlannerOut:
    """Check the code, dry-run it in the sandbox, and store it as the next version of `name`."""
    limits = PackageLimits(max_upload_bytes=int(settings.max_planner_upload_mib * 1024 * 1024),
                           max_unpacked_bytes=int(settings.max_planner_unpacked_mib * 1024 * 1024),
                           max_files=settings.max_planner_files)
    length = request.headers.get("content-length")
    if length is not None and length.isdigit() and int(length) > limits.max_upload_bytes + 65536:
        raise HTTPException(413, f"upload too large: at most {settings.max_planner_upload_mib:g}"
                                 " MiB")
    _check_name_free(session, name, user)
    data = file.file.read(limits.max_upload_bytes + 1)
    if len(data) > limits.max_upload_bytes:
        raise HTTPException(413, f"upload too large: at most {settings.max_planner_upload_mib:g}"
                                 " MiB")
    # The check takes seconds: no transaction (on SQLite, the write lock) is held during it.
    session.commit()
    try:
        slots: CheckSlots = request.app.state.check_slots
        with slots.taken():
            package, check = _check(request, file.filename or "", data, limits)
    except ChecksBusyError as exc:
        raise HTTPException(429, str(exc),
                            headers={"Retry-After": str(CHECKS_RETRY_AFTER_S)}) from None
    _check_name_free(session, name, user)  # another user may have taken it meanwhile
    version = (session.scalar(select(func.max(PlannerRow.version)).where(
        PlannerRow.name == name)) or 0) + 1
    key = f"planners/{name}/v{version}/code.zip"
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "code.zip"
        path.write_bytes(package.zip_bytes)
        try:
            stored = settings_store(settings).put(key, path)
        except ArtifactStoreError as exc:
            raise HTTPException(503, f"could not store the planner: {exc}") from None
    row = PlannerRow(name=name, version=version, builtin=False, owner_id=user.id,
                     description=description, code_hash=package.code_hash,
                     config={"code": stored.location,
                             "check": {"passed": True, "output": check.output[-4000:],
                                       "wall_s": round(check.wall_s, 2)}})
    session.add(row)
    try:
        session.commit()
    except IntegrityError:
        session.rollback()
        raise HTTPException(409, f"another version of {name!r} was stored at the same time; "
                                 "try again") from None
    return planner_out(row, user.name, for_owner=True)


def _check_name_free(session: Session, name: str, user: User) -> None:
    """`HTTPException` when `name` is a built-in planner's or another user's."""
    builtin = session.scalar(select(PlannerRow).where(PlannerRow.name == name,
                                                      PlannerRow.builtin.is_(True)))
    if builtin is not None:
        raise HTTPException(409, f"{name!r} is a built-in planner's name; choose another")
    owner = session.scalar(select(PlannerRow.owner_id).where(PlannerRow.name == name))
    if owner is not None and owner != user.id and not user.is_admin:
        raise HTTPException(403, f"planner {name!r} belongs to another user")


def _check(request: Request, filename: str, data: bytes,
           limits: PackageLimits) -> tuple[PlannerPackage, CheckOutcome]:
    """The static checks and the dry run of an upload; `HTTPException` when it is refused or
    cannot be checked here."""
    try:
        package = load_package(filename, data, limits)
    except PackageError as exc:
        raise HTTPException(422, f"planner rejected: {exc}") from None
    dry_run: PlannerCheck | None = request.app.state.planner_check
    if dry_run is None:
        raise HTTPException(503, "this service was started without the planner sandbox and "
                                 "cannot check uploaded planners")
    try:
        check = dry_run(package)
    except CheckUnavailableError as exc:
        raise HTTPException(503, f"uploaded planners cannot be checked here: {exc}") from None
    if not check.passed:
        raise HTTPException(422, f"planner rejected by its dry run: {check.output[-3000:]}")
    return package, check
