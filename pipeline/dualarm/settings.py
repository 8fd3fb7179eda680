"""Settings objects: frozen dataclasses (or frozen pydantic models), one per method and stage.

They are changed only by making a copy with some fields replaced.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, TypeVar

from pydantic import BaseModel, ValidationError

from dualarm.errors import InvalidArgumentError

S = TypeVar("S")


def with_overrides(settings: S, overrides: Mapping[str, Any]) -> S:
    """A copy of ``settings`` with ``overrides`` (field name -> value), validated like the original.

    Raises:
        InvalidArgumentError: an unknown field (listing the known ones) or a value its class refuses.
    """
    if isinstance(settings, BaseModel):
        _check_keys(settings, set(type(settings).model_fields), overrides)
        try:
            return type(settings).model_validate({**settings.model_dump(), **overrides}) if overrides else settings
        except ValidationError as exc:
            first = exc.errors()[0]
            raise InvalidArgumentError(".".join(str(p) for p in first["loc"]), first["msg"]) from None
    if dataclasses.is_dataclass(settings) and not isinstance(settings, type):
        _check_keys(settings, {f.name for f in dataclasses.fields(settings)}, overrides)
        return dataclasses.replace(settings, **overrides)
    raise InvalidArgumentError("settings", f"expected a dataclass or a pydantic model, got {type(settings).__name__}")


def _check_keys(settings: object, known: set[str], overrides: Mapping[str, Any]) -> None:
    for key in overrides:
        if key not in known:
            raise InvalidArgumentError(
                key, f"not a setting of {type(settings).__name__} (settings: {', '.join(sorted(known))})"
            )


def as_record(settings: Any) -> dict[str, Any]:
    """``settings`` as a JSON-ready dict (for a run's manifest)."""
    if isinstance(settings, BaseModel):
        return settings.model_dump(mode="json")
    return {f.name: _plain(getattr(settings, f.name)) for f in dataclasses.fields(settings)}


def _plain(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return as_record(value)
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    return value


def check_positive(settings: object, *names: str, zero: bool = False, integer: bool = False) -> None:
    """Refuse each field ``names`` of ``settings`` that is not a finite number > 0 (>= 0 with ``zero``).

    With ``integer`` the fields must be integers too (a bool is neither).

    Raises:
        InvalidArgumentError: naming the first field at fault and its value.
    """
    wanted = f"a {'non-negative' if zero else 'positive'} {'integer' if integer else 'number'}"
    for name in names:
        value = getattr(settings, name)
        typed = isinstance(value, int) if integer else isinstance(value, (int, float)) and math.isfinite(value)
        if isinstance(value, bool) or not typed or value < 0 or (value == 0 and not zero):
            raise InvalidArgumentError(name, f"must be {wanted}, not {value!r}")
