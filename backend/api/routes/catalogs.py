"""Target catalogs: list, add, activate."""

from __future__ import annotations

import asyncio
from typing import Annotated

from fastapi import APIRouter, HTTPException, Path, status

from backend.api.contract import errors
from backend.api.deps import ReadAuth, SessionDep, StateDep, WriteAuth, unprocessable
from backend.api.schemas.catalogs import (
    ActiveCatalogPublic,
    CatalogCreate,
    CatalogPublic,
    ReflectorModel,
)
from backend.services.store import (
    add_catalog,
    find_catalog,
    save_device_settings,
    stored_catalogs,
)
from tofpose.core.catalog import BUILTIN_CATALOGS, Catalog, Reflector

router = APIRouter(prefix="/api/catalogs", tags=["catalogs"])
NameParam = Annotated[str, Path(min_length=1, max_length=128)]


def _reflector(r: ReflectorModel) -> Reflector:
    x, y, z = r.position_mm  # three: the schema's length
    return Reflector(r.id, (x, y, z), r.diameter_mm)


def _public(name: str, cat: Catalog, *, builtin: bool, active: str) -> CatalogPublic:
    return CatalogPublic(
        name=name,
        builtin=builtin,
        active=name == active,
        reflectors=[
            ReflectorModel(id=r.id, position_mm=list(r.position_mm), diameter_mm=r.diameter_mm)
            for r in cat.reflectors
        ],
    )


@router.get("", dependencies=[ReadAuth])
def list_catalogs(state: StateDep, session: SessionDep) -> list[CatalogPublic]:
    """Built-in catalogs first, then the ones added through the API."""
    active = state.acquisition.catalog_name
    out = [_public(n, make(), builtin=True, active=active) for n, make in BUILTIN_CATALOGS.items()]
    out += [_public(n, c, builtin=False, active=active) for n, c in stored_catalogs(session)]
    return out


@router.post(
    "", status_code=status.HTTP_201_CREATED, dependencies=[WriteAuth], responses=errors(409)
)
def create_catalog(body: CatalogCreate, state: StateDep, session: SessionDep) -> CatalogPublic:
    """Add a catalog (positions in the target frame, mm). 409 if the name exists; 422 if
    the geometry is unusable (duplicate ids, collinear, ...)."""
    if find_catalog(session, body.name) is not None:
        raise HTTPException(409, f"a catalog named {body.name!r} already exists")
    try:
        cat = Catalog(
            body.name,
            tuple(_reflector(r) for r in body.reflectors),
        )
    except ValueError as exc:
        raise unprocessable(["body", "reflectors"], [f"catalog rejected: {exc}"]) from exc
    # NameTakenError (409): lost a race with a concurrent request for the same name
    add_catalog(session, body.name, cat)
    return _public(body.name, cat, builtin=False, active=state.acquisition.catalog_name)


@router.get("/{name}", dependencies=[ReadAuth], responses=errors(404))
def get_catalog(name: NameParam, state: StateDep, session: SessionDep) -> CatalogPublic:
    cat = find_catalog(session, name)
    if cat is None:
        raise HTTPException(404, f"no catalog named {name!r}")
    return _public(
        name, cat, builtin=name in BUILTIN_CATALOGS, active=state.acquisition.catalog_name
    )


@router.post("/{name}/activate", dependencies=[WriteAuth], responses=errors(404, 409, 503, 504))
async def activate_catalog(name: NameParam, state: StateDep) -> ActiveCatalogPublic:
    """Make the live pipeline use this catalog (kept across restarts)."""

    def lookup() -> Catalog | None:
        with state.sessions() as session:
            return find_catalog(session, name)

    cat = await asyncio.to_thread(lookup)
    if cat is None:
        raise HTTPException(404, f"no catalog named {name!r}")
    try:
        await asyncio.wait_for(asyncio.wrap_future(state.acquisition.set_catalog(name, cat)), 10.0)
    except TimeoutError as exc:
        raise HTTPException(504, "the acquisition loop did not switch catalogs in time") from exc
    except RuntimeError as exc:  # acquisition stopped (shutting down)
        raise HTTPException(503, f"the catalog was not switched: {exc}") from exc

    def persist() -> None:
        with state.sessions() as session:
            save_device_settings(session, "pipeline", {"catalog": name})

    await asyncio.to_thread(persist)
    return ActiveCatalogPublic(catalog=name)
