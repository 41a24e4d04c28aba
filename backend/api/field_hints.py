"""The valid field names closest to an unknown one in a request body, so that a 422 for
a typo says what was meant ("'rail_mm' is not a field here; did you mean 'rails_mm'?")
instead of Pydantic's bare "Extra inputs are not permitted".

The body's model is the route's (``APIRoute.body_field``); an error's ``loc`` walks
into it (``("body", "generator", "rail_mm")``): through nested models, lists and dicts
(an int or key step), and unions (every member is followed, a discriminated union's tag
step skipped).
"""

from __future__ import annotations

import difflib
import types
import typing
from collections.abc import Sequence

from pydantic import BaseModel

#: how close a valid name must be to be offered (difflib's ratio)
CUTOFF = 0.6
#: at most this many valid names are listed when none is close
MAX_LISTED = 12


def _members(annotation: object) -> list[object]:
    """The types an annotation may hold: Optional, Annotated, unions, list / dict items."""
    origin = typing.get_origin(annotation)
    if origin is typing.Annotated:
        return _members(typing.get_args(annotation)[0])
    if origin in (typing.Union, types.UnionType):
        return [m for a in typing.get_args(annotation) for m in _members(a)]
    return [annotation]


def _model_fields(model: type[BaseModel]) -> set[str]:
    """A model's field names and their aliases, as a body may spell them."""
    names = set(model.model_fields)
    names |= {f.alias for f in model.model_fields.values() if f.alias}
    return names


def fields_at(annotation: object, path: Sequence[str | int]) -> set[str]:
    """The field names valid at ``path`` inside a value of type ``annotation`` (empty
    when the path does not lead to a model)."""
    found: set[str] = set()
    for member in _members(annotation):
        origin = typing.get_origin(member)
        if origin in (list, tuple, set, frozenset, dict) or (
            isinstance(origin, type) and issubclass(origin, (Sequence, dict))
        ):
            args = typing.get_args(member)
            if path and args:
                found |= fields_at(args[-1], path[1:])
            continue
        if not (isinstance(member, type) and issubclass(member, BaseModel)):
            continue
        if not path:
            found |= _model_fields(member)
            continue
        step = path[0]
        field = member.model_fields.get(str(step))
        if field is None:  # an alias, or a discriminated union's tag step
            field = next(
                (f for f in member.model_fields.values() if f.alias == step),
                None,
            )
        if field is not None:
            found |= fields_at(field.annotation, path[1:])
        elif _tagged(member, step):
            found |= fields_at(member, path[1:])
    return found


def _tagged(model: type[BaseModel], tag: str | int) -> bool:
    """Whether one of the model's fields is a ``Literal`` holding ``tag`` (the member of
    a discriminated union that Pydantic names in ``loc`` by its tag)."""
    for field in model.model_fields.values():
        for member in _members(field.annotation):
            if typing.get_origin(member) is typing.Literal and tag in typing.get_args(member):
                return True
    return False


def unknown_field_message(unknown: str, valid: set[str]) -> str:
    """Pydantic's message for an extra input, with the closest valid name (or the valid
    names, when there are few and none is close)."""
    close = difflib.get_close_matches(unknown, sorted(valid), n=1, cutoff=CUTOFF)
    said = f"Extra inputs are not permitted: '{unknown}' is not a field here"
    if close:
        return f"{said}; did you mean '{close[0]}'?"
    if valid and len(valid) <= MAX_LISTED:
        return f"{said} (valid: {', '.join(repr(v) for v in sorted(valid))})"
    return said
