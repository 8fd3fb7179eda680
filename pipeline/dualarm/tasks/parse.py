"""A task file read and validated against the schema; errors name the file and the key at fault."""

from __future__ import annotations

import tomllib
from pathlib import Path

from pydantic import ValidationError
from pydantic_core import ErrorDetails

from dualarm.errors import TaskFileError, excerpt
from dualarm.files import read_text
from dualarm.tasks.schema import TaskSpec


def _key_path(error: ErrorDetails, data: object) -> str:
    """The task-file key of a pydantic error.

    Location parts that are not keys of the input (the names pydantic gives union members, such as
    ``str`` or ``constrained-float``) are dropped by walking the input alongside; a missing key is
    the one part kept that the input lacks.
    """
    out: str = ""
    node = data
    loc = error["loc"]
    for i, part in enumerate(loc):
        if isinstance(node, list) and isinstance(part, int) and part < len(node):
            out, node = f"{out}[{part}]", node[part]
        elif isinstance(node, dict) and part in node:
            out, node = (f"{out}.{part}" if out else str(part)), node[part]
        elif error["type"] == "missing" and i == len(loc) - 1:
            out = f"{out}[{part}]" if isinstance(part, int) else f"{out}.{part}" if out else str(part)
    return excerpt(out) if out else "(top level)"


def _quoted(value: object) -> str:
    """``repr(value)``, quoted with :func:`~dualarm.errors.excerpt`.

    A value nested too deeply for repr is described.
    """
    try:
        return excerpt(repr(value))
    except RecursionError:
        return f"a {type(value).__name__} nested too deeply"


def _validation_message(file: object, exc: ValidationError, data: object) -> str:
    errors = [(_key_path(e, data), e) for e in exc.errors()]
    key, first = max(errors, key=lambda ke: ke[0].count(".") + ke[0].count("["))  # the most specific
    alternatives = [e for k, e in errors if k == key]
    fitting = [e for e in alternatives if not e["type"].endswith("_type")]  # those whose type the value has
    if first["type"] == "extra_forbidden":
        message = "unknown key"
    elif first["type"] == "missing":
        message = "missing"
    elif len(alternatives) > 1 and len(fitting) == 1:  # a union, and the value has the type of one member
        message = fitting[0]["msg"].removeprefix("Value error, ")
    elif len(alternatives) > 1:  # a union: say what each alternative wanted
        message = (
            f"wrong type or value {_quoted(first['input'])} "
            f"({'; or '.join(e['msg'].removeprefix('Value error, ') for e in alternatives)})"
        )
    else:
        message = first["msg"].removeprefix("Value error, ")
    others = len({k for k, _ in errors}) - 1
    return f"{excerpt(file)}:{key}: {message}" + (
        f" (and {others} more problem{'s' if others > 1 else ''})" if others else ""
    )


def _read(file: Path) -> tuple[str, dict]:
    """The text of a task file and its TOML.

    One-line TaskFileError naming the file and the cause otherwise (see :func:`dualarm.files.read_text`).
    """
    text = read_text(file, "task file", TaskFileError)
    try:
        return text, tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise TaskFileError(f"{excerpt(file)}: not valid TOML: {exc}") from None
    except (RecursionError, ValueError) as exc:  # nesting beyond Python's stack, an integer beyond int()'s digits
        raise TaskFileError(
            f"{excerpt(file)}: not valid TOML: "
            f"{excerpt(exc) if isinstance(exc, ValueError) else 'tables or arrays nested too deeply'}"
        ) from None


def _validate(where: str, data: object) -> TaskSpec:
    try:
        return TaskSpec.model_validate(data)
    except ValidationError as exc:
        raise TaskFileError(_validation_message(where, exc, data)) from None
    except RecursionError:
        raise TaskFileError(f"{excerpt(where)}: values nested too deeply") from None
