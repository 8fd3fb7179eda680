"""A griffe extension for the docs build: Sphinx roles in docstrings become cross-references.

dualarm's docstrings are Google style and name other objects with Sphinx roles
(``:func:`dualarm.load_robot```, ``:class:`~dualarm.paths.reference.CartesianReference```,
``:data:`MAX_LINE```). mkdocstrings does not read roles, so once the package is loaded this
rewrites each role into an *optional* autorefs cross-reference: a link where the target is on a
page of the site (the API reference documents ``dualarm.__all__``), its name in code where it is
not. An optional cross-reference never warns, so roles naming internal objects do not break the
strict build. The target is resolved as Sphinx does: in the object's class, then its module,
then from the package root; a target that resolves nowhere is kept as written.

mkdocs.yml loads it: ``plugins: mkdocstrings: handlers: python: options: extensions``.
"""

from __future__ import annotations

import html
import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?:func|class|meth|data|mod|attr|exc|obj|const|type):`(?P<body>[^`]+)`")


def _find(root: griffe.Module, path: str) -> griffe.Object | griffe.Alias | None:
    """The object at dotted ``path`` under ``root`` (``root.path`` included or not), or None."""
    parts = path.split(".")
    if parts[0] == root.name:
        parts = parts[1:]
    obj: Any = root
    try:
        for part in parts:
            obj = obj.members[part]
    except (KeyError, griffe.AliasResolutionError, griffe.CyclicAliasError):
        return None
    return obj


def _canonical(obj: griffe.Object | griffe.Alias, path: str) -> str:
    """Where an imported name is defined (mkdocstrings registers that path for what it renders)."""
    try:
        return obj.final_target.path if obj.is_alias else obj.path
    except (griffe.AliasResolutionError, griffe.CyclicAliasError):
        return path


def _scopes(obj: griffe.Object | griffe.Alias) -> list[str]:
    """Where a relative target is looked up, innermost first: the class (if any), the module."""
    scopes = []
    current: Any = obj if obj.is_class else obj.parent
    while current is not None:
        if current.is_class or current.is_module:
            scopes.append(current.path)
        if current.is_module:
            break
        current = current.parent
    return scopes


def _reference(root: griffe.Module, obj: griffe.Object, body: str) -> str:
    """The HTML of one role: an optional cross-reference with the title Sphinx would show."""
    body = body.strip()
    explicit = re.fullmatch(r"(?P<title>.*?)\s*<(?P<target>[^>]+)>", body, re.S)
    if explicit:
        title, target = explicit["title"].strip(), explicit["target"].strip()
    else:
        target = body.lstrip("!")
        title = target.lstrip("~.").rsplit(".", 1)[-1] if target.startswith("~") else target.lstrip(".")
    target = target.lstrip("~.!")
    identifier = target
    for scope in [*_scopes(obj), root.path]:
        for candidate in (f"{scope}.{target}", target):
            found = _find(root, candidate) if candidate.split(".")[0] == root.name else None
            if found is not None:
                identifier = _canonical(found, candidate)
                break
        else:
            continue
        break
    return f'<autoref identifier="{html.escape(identifier)}" optional><code>{html.escape(title)}</code></autoref>'


class SphinxRoles(griffe.Extension):
    """Rewrite the Sphinx roles of every docstring of a loaded package into cross-references."""

    def on_package(self, *, pkg: griffe.Module, loader: griffe.GriffeLoader, **kwargs: Any) -> None:
        """Visit every object of the package once it is fully loaded (so every target exists)."""
        seen: set[int] = set()

        def visit(obj: Any) -> None:
            if obj.is_alias or id(obj) in seen:
                return
            seen.add(id(obj))
            if obj.docstring is not None and ":`" in obj.docstring.value:
                obj.docstring.value = ROLE.sub(lambda m: _reference(pkg, obj, m["body"]), obj.docstring.value)
            for member in obj.members.values():
                visit(member)

        visit(pkg)
