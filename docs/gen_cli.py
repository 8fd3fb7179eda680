"""Generate the command-line reference from the Typer app itself, so the page cannot drift.

mkdocs-gen-files runs this script at every build (``mkdocs.yml``: ``plugins: gen-files``). It
walks ``typer.main.get_command(dualarm.cli.app)`` -- every command, group and sub-command, as
``dualarm ... --help`` shows them -- and appends the reference to ``cli.md`` (whose hand-written
introduction stays in ``docs/cli.md``). ``python docs/gen_cli.py`` prints the generated part.
"""

from __future__ import annotations

import html
import re
from typing import Any

import typer

from dualarm.cli import app

PROG = "dualarm"
PAGE = "cli.md"


def escape(text: str) -> str:
    """Help text as Markdown that renders as written: no emphasis, no HTML, no links, no table breaks."""
    text = html.escape(text, quote=False)
    return re.sub(r"([\\`*_{}\[\]|#])", r"\\\1", text)


def paragraphs(text: str | None) -> str:
    """A help text's paragraphs (click's no-rewrap marker, a backspace line, dropped), escaped."""
    if not text:
        return ""
    blocks = [block.replace("\b\n", "").strip() for block in text.strip().split("\n\n")]
    return "\n\n".join(escape(block) for block in blocks if block) + "\n\n"


# Typer builds click objects (its own vendored copy of click in recent versions), so they are
# recognised by what they have, not by class: a group has ``commands``, a parameter a
# ``param_type_name`` ("argument" or "option"), and every command its ``context_class``.
Command = Context = Any


def context(command: Command, name: str, parent: Context | None = None) -> Context:
    """The context ``--help`` would see for ``command`` invoked as ``name`` under ``parent``."""
    return command.context_class(command, info_name=name, parent=parent)


def parameters(command: Command, ctx: Context) -> str:
    """The command's arguments and options as two tables, as ``--help`` lists them."""
    out = []
    for kind, title in (("argument", "Arguments"), ("option", "Options")):
        rows = []
        for param in command.get_params(ctx):
            if param.param_type_name != kind or getattr(param, "hidden", False):
                continue
            record = param.get_help_record(ctx)
            if record is None:  # a plain click argument has no help record
                record = (param.make_metavar(ctx), "")
            names, help_text = record
            rows.append(f"| `{names.replace('|', '&#124;')}` | {escape(' '.join(help_text.split()))} |")
        if rows:
            out += [f"**{title}**", "", f"| {title[:-1].lower()} | description |", "|---|---|", *rows, ""]
    return "\n".join(out) + "\n" if out else ""


def render_command(command: Command, ctx: Context, level: int) -> str:
    """One command's section, then its sub-commands' (for a group), one heading level down."""
    path = ctx.command_path
    text = f"{'#' * level} {path}\n\n"
    text += f"```text\n{command.get_usage(ctx)}\n```\n\n"
    text += paragraphs(command.help)
    text += parameters(command, ctx)
    if hasattr(command, "commands"):
        names = [name for name in command.list_commands(ctx) if not command.commands[name].hidden]
        text += "**Commands**\n\n| command | what it does |\n|---|---|\n"
        for name in names:
            sub = command.commands[name]
            anchor = f"{path} {name}".replace(" ", "-")
            text += f"| [`{path} {name}`](#{anchor}) | {escape(sub.get_short_help_str(limit=200))} |\n"
        text += "\n"
        for name in names:
            sub = command.commands[name]
            # The root's commands sit beside it (``## dualarm run``), a group's one level down.
            text += render_command(sub, context(sub, name, ctx), level + 1 if ctx.parent else level)
    return text


def render() -> str:
    """The whole reference: ``dualarm`` and, below it, every command and sub-command."""
    root = typer.main.get_command(app)
    return render_command(root, context(root, PROG), 2)


if __name__ == "__main__":
    print(render())
else:
    import mkdocs_gen_files

    with mkdocs_gen_files.open(PAGE, "a") as page:
        page.write("\n" + render())
