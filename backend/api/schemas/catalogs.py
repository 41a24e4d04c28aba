"""Reflector catalogs (/api/catalogs)."""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, Field

from backend.api.schemas.common import StrictBody


class ReflectorModel(StrictBody):
    id: int = Field(ge=0, le=1_000_000)
    position_mm: list[Annotated[float, Field(ge=-1e6, le=1e6)]] = Field(
        min_length=3, max_length=3, description="centre in the target frame, mm"
    )
    diameter_mm: float = Field(gt=0, le=10_000)


class CatalogCreate(StrictBody):
    name: str = Field(min_length=1, max_length=128, pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
    reflectors: list[ReflectorModel] = Field(min_length=3, max_length=256)


class CatalogPublic(BaseModel):
    name: str
    builtin: bool
    active: bool
    reflectors: list[ReflectorModel]


class ActiveCatalogPublic(BaseModel):
    catalog: str
