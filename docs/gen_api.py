"""Generate the API reference page: every name of ``dualarm.__all__``, from its docstring.

mkdocs-gen-files runs this script at every build (``mkdocs.yml``: ``plugins: gen-files``). It
appends to ``api.md`` (whose introduction stays in ``docs/api.md``) a mkdocstrings block
(``::: dualarm.NAME``) per public name, grouped by the sub-package that defines it (read
statically by griffe from the stub ``dualarm/__init__.pyi``), so a name added to or moved within
the API appears without editing the docs.
``python docs/gen_api.py`` prints the generated part.
"""

from __future__ import annotations

from pathlib import Path

import griffe

import dualarm

PAGE = "api.md"
SOURCE_ROOT = Path(__file__).resolve().parents[1] / "pipeline"

#: Section titles of the sub-packages, in the order of the data flow; others follow, by name.
SECTIONS = {
    "model": "Robots",
    "tasks": "Tasks",
    "paths": "References",
    "ik": "Inverse kinematics",
    "methods": "The registry of methods",
    "plan": "Planning",
    "retime": "Timing",
    "smooth": "Smoothing and the approach",
    "execute": "Execution",
    "contracts": "Contracts between stages",
    "stages": "Stages",
    "run": "The pipeline",
    "verdict": "Verdicts",
    "record": "Sinks and reading runs back",
    "study": "Studies",
    "errors": "Errors",
    "version": "Version",
}


def sections() -> dict[str, list[str]]:
    """The public names per sub-package of ``dualarm`` that defines them (the stub's imports)."""
    package = griffe.load("dualarm", search_paths=[str(SOURCE_ROOT)], resolve_aliases=False)
    grouped: dict[str, list[str]] = {}
    for name in dualarm.__all__:
        member = package.members.get(name)
        target = member.target_path if member is not None and member.is_alias else f"dualarm.{name}"
        part = target.split(".")[1] if target.count(".") > 1 else target.split(".")[-1]
        grouped.setdefault(part, []).append(name)
    order = [*(p for p in SECTIONS if p in grouped), *sorted(p for p in grouped if p not in SECTIONS)]
    return {p: grouped[p] for p in order}


def render() -> str:
    """A heading per sub-package and a block per name (appended to the introduction in api.md)."""
    text = ""
    for part, names in sections().items():
        text += f"## {SECTIONS.get(part, f'`dualarm.{part}`')}\n\n"
        for name in names:
            text += f"::: dualarm.{name}\n\n"
    return text


if __name__ == "__main__":
    print(render())
else:
    import mkdocs_gen_files

    with mkdocs_gen_files.open(PAGE, "a") as page:
        page.write("\n" + render())
