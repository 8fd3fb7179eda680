"""Every script in examples/ runs with dualarm installed from its wheel, from a directory of its
own, and prints what it claims.

The printed figures are checked against bounds a correct run must meet (the pose error of a
closed-form solution, the tracking of TV-GDD and of the executed motion), and the recorded run of
example 03 is read back from disk.
"""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((REPO / "examples").glob("[0-9][0-9]_*.py"))


def run_example(python: Path, path: Path, cwd: Path) -> str:
    done = subprocess.run([str(python), str(path)], cwd=cwd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def number(pattern: str, text: str) -> float:
    match = re.search(pattern, text)
    assert match, f"{pattern!r} not in the output:\n{text}"
    return float(match.group(1))


def test_examples_are_numbered_and_short():
    assert [p.name[:2] for p in EXAMPLES] == [f"{i:02d}" for i in range(1, len(EXAMPLES) + 1)]
    for path in EXAMPLES:
        code = [line for line in path.read_text().splitlines() if line.strip() and not line.lstrip().startswith("#")]
        assert len(code) <= 30, f"{path.name}: {len(code)} lines of code"


@pytest.mark.integration
@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_runs(path: Path, tmp_path: Path, wheel_env: Path):
    out = run_example(wheel_env / "bin" / "python", path, tmp_path)
    if path.stem.startswith("01"):
        assert (
            out.count(" valid") + out.count("singular") + out.count("outside limits") + out.count("out of reach") >= 8
        )
        assert number(r"position error \[m\]: (\S+)", out) < 1e-9
    elif path.stem.startswith("02"):
        assert number(r"largest hand position error: (\S+) m", out) < 1e-3
    elif path.stem.startswith("03"):
        directory = tmp_path / out.splitlines()[0].removeprefix("recorded ")
        assert json.loads((directory / "manifest.json").read_text())["status"] == "complete"
        assert number(r"between repetitions \[rad\]: (\S+)", out) < 1e-9
    elif path.stem.startswith("04"):
        assert "found a path: True" in out
    elif path.stem.startswith("05"):
        assert number(r"hand tracking error (\S+) m", out) < 1e-3
        assert not list(tmp_path.iterdir()), "a run in memory writes no file"
    elif path.stem.startswith("06"):
        assert number(r"mc-inverse, (\d+) trials solved", out) >= 1
        assert number(r"between repetitions (\S+) rad", out) < 1e-9
        assert "report: report.md" in out


#: The pages a reader sees: the README, the documentation site's sources and the data READMEs.
DOCS = [
    REPO / "README.md",
    *sorted((REPO / "docs").rglob("*.md")),
    REPO / "tasks" / "README.md",
    REPO / "reports" / "README.md",
]


def python_blocks(doc: Path) -> list[str]:
    return re.findall(r"^ *```python\n(.*?)^ *```", doc.read_text(), re.S | re.M)


def test_docs_show_the_first_two_examples_as_they_are():
    """The Python page (docs/python.md) shows examples 01 and 02, the README 01; every copy is the file."""
    shown = {doc: python_blocks(doc) for doc in DOCS}
    for path in EXAMPLES[:2]:
        assert path.read_text().rstrip() + "\n" in shown[REPO / "docs" / "python.md"], (
            f"docs/python.md's copy of {path.name} differs from the file"
        )
    assert EXAMPLES[0].read_text().rstrip() + "\n" in shown[REPO / "README.md"], (
        f"README's copy of {EXAMPLES[0].name} differs from the file"
    )
    for path in EXAMPLES:
        first = path.read_text().splitlines()[0]
        for doc, blocks in shown.items():
            for block in blocks:
                if block.splitlines()[:1] == [first]:
                    assert block == path.read_text().rstrip() + "\n", (
                        f"{doc.relative_to(REPO)}'s copy of {path.name} differs from the file"
                    )


def test_readme_links_only_inside_the_repository():
    for doc in DOCS:
        for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", doc.read_text()):
            if "://" not in target:
                assert (doc.parent / target).resolve().is_relative_to(REPO), (
                    f"{doc.name} links outside the repository: {target}"
                )
                assert (doc.parent / target).exists(), f"{doc.name} links to a missing file: {target}"
        assert "../shared" not in doc.read_text(), f"{doc.name} points at ../shared"


def test_docs_link_only_to_pages():
    """The site's pages link to pages of the site, never to files outside docs/ (mkdocs --strict refuses them)."""
    docs = REPO / "docs"
    for doc in sorted(docs.rglob("*.md")):
        for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", doc.read_text()):
            if "://" not in target:
                assert (doc.parent / target).resolve().is_relative_to(docs), (
                    f"{doc.relative_to(REPO)} links outside docs/: {target}"
                )
