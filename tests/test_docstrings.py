"""Every docstring of the package opens with a one-line summary of at most 100 characters (DESIGN.md,
"How code should read"); details go below it, after a blank line.

Run as a script (``python tests/test_docstrings.py [PATH ...]``) it lists the docstrings that do not.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "pipeline" / "dualarm"
#: The longest summary line [characters].
SUMMARY_MAX = 100


def long_summaries(root: Path) -> list[str]:
    """``file:line name`` of each docstring under ``root`` whose summary is not one line of at most 100 characters."""
    found = []
    for path in sorted(root.rglob("*.py")) if root.is_dir() else [root]:
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            if not isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            doc = ast.get_docstring(node, clean=True)
            if doc is None:
                continue
            summary = doc.strip().split("\n\n")[0]
            if "\n" in summary or len(summary) > SUMMARY_MAX:
                line = node.body[0].lineno if node.body else 1
                name = getattr(node, "name", "module")
                found.append(f"{path}:{line} {name} ({len(summary.splitlines())} lines, {len(summary)} chars)")
    return found


def test_every_docstring_summary_is_one_line_of_at_most_100_characters():
    found = long_summaries(PACKAGE)
    assert not found, f"{len(found)} docstrings:\n" + "\n".join(found)


def test_the_check_finds_a_long_and_a_wrapped_summary(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text(
        '"""Fine."""\n\n\ndef f():\n    """'
        + "x" * 101
        + '"""\n\n\ndef g():\n    """Two\n    lines.\n\n    Body.\n    """\n'
    )
    assert [f.split(" ")[1] for f in long_summaries(bad)] == ["f", "g"]


if __name__ == "__main__":
    hits = [h for arg in sys.argv[1:] or [str(PACKAGE)] for h in long_summaries(Path(arg).resolve())]
    print("\n".join(hits) or "none", f"\n{len(hits)} docstrings", sep="")
