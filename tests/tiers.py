"""The test tiers' guard: a unit test (not marked ``integration``) may not do what makes a test an integration test.

Two tiers (``pyproject.toml`` registers the marker; ``make test-fast`` runs ``-m "not integration"``):

- **unit**: in this process, the project's functions on their own inputs: no simulator, no cluster, no child process,
  no viewer, no run recorded to disk;
- **integration** (``@pytest.mark.integration``, or ``pytestmark`` for a whole module): a test that connects to
  PyBullet, starts a Dask cluster or client, starts a process (a CLI in a child, pip, mypy, Node.js, a browser),
  starts Rerun's viewer, or records a run (the whole pipeline into a run directory: ``record_run``, the CLI's ``run``,
  ``consistency`` and ``plan``, a study's trial), itself or in a fixture it gets.

:func:`installed` wraps the calls that do those: ``pybullet.connect``; ``distributed.LocalCluster`` and
``distributed.Client`` (their ``__init__``); ``subprocess.Popen`` (so ``run``, ``check_output``, asyncio's and
Playwright's children), ``os.system``, ``os.fork``, ``os.posix_spawn[p]`` and ``multiprocessing``'s ``Process.start``
(so process pools and Dask's nannies); ``rerun_bindings.spawn`` (Rerun's viewer, started from Rust); and
``dualarm.run.record_stages``, which every recorded run goes through. Modules not imported yet are wrapped when they
are (an import hook), so the guard loads none of them. A unit test that calls one fails with :class:`TierViolation`, a
``BaseException`` so that no ``except Exception`` in the code under test swallows it (and the test's report is failed
even if something did); so does a unit test that gets a module- or session-scoped fixture which made such a call when
it was set up for an earlier test (:func:`check_fixtures`), so that ``make test`` judges each test as ``make
test-fast`` does.

One child process is allowed to a unit test: the C compiler that :func:`dualarm.numerics.compiled.compiled` runs to
build CasADi's generated code (a cached build step of the numerics, like writing a file, not a program under test):
the call comes from ``dualarm/numerics/compiled.py`` and its command starts with that module's own compiler and
``FLAGS``.

With ``DUALARM_TIER_RECORD=FILE`` the guard records instead (one JSON line per call: test id, what) and lets the call
through: how the tests that need the marker were found (``pytest -m "not integration"`` with it set lists those left).
"""

from __future__ import annotations

import functools
import importlib.abc
import importlib.machinery
import json
import multiprocessing.process
import os
import shlex
import subprocess
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import ModuleType
from typing import Any

import pytest

#: The marker of the integration tier.
MARKER = "integration"
#: Environment variable: record the calls a unit test makes into this file instead of failing it.
RECORD = "DUALARM_TIER_RECORD"
#: The guarded calls a unit test made, per test (read by the report hook).
VIOLATIONS = pytest.StashKey[list[str]]()

#: The test whose setup, call or teardown runs now (set by the ``pytest_runtest_protocol`` hook), else None.
current: pytest.Item | None = None
#: The fixtures being set up now, innermost last (``pytest_fixture_setup``): ``path::name``, where each is defined.
fixtures: list[str] = []


class TierViolation(BaseException):
    """A unit test started what only an integration test may (a ``BaseException``: ``except Exception`` lets it by)."""


def is_unit(item: pytest.Item) -> bool:
    """Whether ``item`` is in the unit tier (not marked :data:`MARKER`)."""
    return item.get_closest_marker(MARKER) is None


def check(what: str, detail: str) -> None:
    """Fail the current test if it is in the unit tier (or record the call, with :data:`RECORD` set).

    A fixture making the call is remembered in :data:`touching`, whichever test it is set up for: a unit test that
    later gets the same (module- or session-scoped) fixture fails too (:func:`check_fixtures`), so that the full run,
    where an integration test may set it up first, judges a unit test as the unit tier alone does.
    """
    item = current
    fixture = fixtures[-1] if fixtures else None
    if fixture is not None:
        touching.setdefault(fixture, f"{what} ({detail[:200]})")
    if item is not None and is_unit(item):
        fail(item, f"{f' in its fixture {fixture}' if fixture else ''} {what} ({detail[:200]})")


#: Fixtures (``path::name``) whose setup made a guarded call, and what it was.
touching: dict[str, str] = {}


def fixture_key(definition: pytest.FixtureDef) -> str:
    """A fixture as :data:`fixtures` and :data:`touching` name it: where it is defined, and its name."""
    return f"{definition.baseid}::{definition.argname}"


def fixture_keys(item: pytest.Item) -> set[str]:
    """The fixtures ``item`` gets (its fixture closure, each name's innermost definition)."""
    info = getattr(item, "_fixtureinfo", None)
    if info is None:
        return set()
    return {fixture_key(definitions[-1]) for definitions in info.name2fixturedefs.values() if definitions}


def check_fixtures(item: pytest.Item) -> None:
    """Fail a unit test that gets a fixture which, set up for an earlier test, made a guarded call."""
    if is_unit(item):
        for key in sorted(fixture_keys(item) & touching.keys()):
            fail(item, f" gets the fixture {key}, which {touching[key]} (set up for an earlier test)")


def fail(item: pytest.Item, what: str) -> None:
    """Raise :class:`TierViolation` for ``item`` (or record it, with :data:`RECORD` set)."""
    record = os.environ.get(RECORD)
    if record:
        with open(record, "a") as f:
            f.write(json.dumps({"test": item.nodeid, "what": what.strip()}) + "\n")
        return
    message = (
        f"{item.nodeid} is a unit test but{what}: the unit tier (make test-fast) runs no PyBullet world, Dask "
        f"cluster, subprocess or viewer and records no run. Mark the test @pytest.mark.{MARKER} (a whole module: "
        f"pytestmark = pytest.mark.{MARKER}), or keep it off that call; see tests/tiers.py."
    )
    item.stash.setdefault(VIOLATIONS, []).append(message)
    raise TierViolation(message)


def _argv(args: Any) -> list[str]:
    if isinstance(args, str | bytes | os.PathLike):
        return shlex.split(os.fsdecode(args)) if isinstance(args, str | bytes) else [os.fspath(args)]
    return [os.fsdecode(a) if isinstance(a, bytes) else str(a) for a in args]


def _is_the_numerics_compiler(argv: list[str]) -> bool:
    """True for the C compiler :mod:`dualarm.numerics.compiled` runs: called from that file, with its command."""
    module = sys.modules.get("dualarm.numerics.compiled")
    if module is None:
        return False
    frame: Any = sys._getframe()
    while frame is not None and frame.f_code.co_filename in (__file__, subprocess.__file__):
        frame = frame.f_back  # the first caller outside this guard and the subprocess module
    if frame is None or frame.f_code.co_filename != module.__file__:
        return False
    command = [module._compiler(), *module.FLAGS]
    return argv[: len(command)] == command


def _check_popen(args: Any) -> None:
    argv = _argv(args)
    if not _is_the_numerics_compiler(argv):
        check("starts a subprocess", shlex.join(argv))


def _wrap(owner: Any, name: str, what: str, detail: Callable[..., str] = lambda *a, **k: "") -> Callable[[], None]:
    """Replace ``owner.name`` by a function that calls :func:`check` first; returns the undo."""
    original = getattr(owner, name)

    @functools.wraps(original)
    def guarded(*args: Any, **kwargs: Any) -> Any:
        check(what, detail(*args, **kwargs))
        return original(*args, **kwargs)

    setattr(owner, name, guarded)
    return lambda: setattr(owner, name, original)


def _wrap_popen() -> Callable[[], None]:
    original = subprocess.Popen.__init__

    @functools.wraps(original)
    def __init__(self: subprocess.Popen, args: Any, *rest: Any, **kwargs: Any) -> None:
        _check_popen(args)
        original(self, args, *rest, **kwargs)

    subprocess.Popen.__init__ = __init__  # type: ignore[method-assign]
    return lambda: setattr(subprocess.Popen, "__init__", original)


#: Per module: what to wrap in it, when it is (or once it is) imported.
_LATER: dict[str, Callable[[ModuleType], Callable[[], None]]] = {
    "pybullet": lambda m: _wrap(m, "connect", "connects to PyBullet", lambda *a, **k: f"pybullet.connect{a}"),
    "distributed.deploy.local": lambda m: _wrap(
        m.LocalCluster, "__init__", "starts a Dask cluster", lambda *a, **k: f"LocalCluster({k})"
    ),
    "distributed.client": lambda m: _wrap(
        m.Client, "__init__", "starts a Dask client", lambda *a, **k: f"Client{a[1:]}"
    ),
    # Rerun's viewer, which rerun.spawn and rerun.experimental.ViewerClient.spawn start from Rust (not subprocess)
    "rerun_bindings": lambda m: _wrap(m, "spawn", "starts Rerun's viewer", lambda *a, **k: f"rerun_bindings.spawn{k}"),
    # a run recorded to disk (record_run, the CLI's run, consistency and plan, a study's trial): the whole pipeline
    "dualarm.run": lambda m: _wrap(m, "record_stages", "records a run", lambda *a, **k: "dualarm.run.record_stages"),
}


class _WrapOnImport(importlib.abc.MetaPathFinder):
    """An import hook: the modules of :data:`_LATER` get their wrappers as soon as they are executed."""

    def __init__(self, undo: list[Callable[[], None]]) -> None:
        self.undo = undo

    def find_spec(self, name: str, path: Any, target: Any = None) -> importlib.machinery.ModuleSpec | None:
        if name not in _LATER:
            return None
        spec = importlib.machinery.PathFinder.find_spec(name, path, target)
        if spec is None or spec.loader is None:
            return None
        loader, undo = spec.loader, self.undo

        class Loader(importlib.abc.Loader):
            def __getattr__(self, attribute: str) -> Any:  # get_source, is_package, get_resource_reader, ...
                return getattr(loader, attribute)

            def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
                return loader.create_module(spec)

            def exec_module(self, module: ModuleType) -> None:
                loader.exec_module(module)
                undo.append(_LATER[name](module))

        spec.loader = Loader()
        return spec


@contextmanager
def installed() -> Iterator[None]:
    """The guard's wrappers in place (and the import hook for modules not imported yet); all undone after."""
    undo = [
        _wrap_popen(),
        _wrap(os, "system", "starts a subprocess", lambda command: f"os.system({command!r})"),
        _wrap(os, "fork", "starts a subprocess", lambda: "os.fork()"),
        _wrap(os, "posix_spawn", "starts a subprocess", lambda path, *a, **k: f"os.posix_spawn({path!r})"),
        _wrap(os, "posix_spawnp", "starts a subprocess", lambda path, *a, **k: f"os.posix_spawnp({path!r})"),
        _wrap(
            multiprocessing.process.BaseProcess,
            "start",
            "starts a subprocess",
            lambda process: f"multiprocessing {process!r}",
        ),
    ]
    undo += [wrap(sys.modules[name]) for name, wrap in _LATER.items() if name in sys.modules]
    hook = _WrapOnImport(undo)
    sys.meta_path.insert(0, hook)
    try:
        yield
    finally:
        sys.meta_path.remove(hook)
        for step in reversed(undo):
            step()
