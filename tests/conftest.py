"""Fixtures and hooks shared by the tests; the helpers they import are in :mod:`tests.helpers`."""

import functools
import json
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests import tiers
from tests.helpers import HUMANOID, OTHER_RUNS, REPO, SHIPPED


def pytest_configure(config: pytest.Config) -> None:
    """A short base temporary directory, made for this run: a one-line message quotes a long path shortened
    (:func:`dualarm.errors.excerpt`), and the tests match whole paths, written for pytest's own base
    (``/tmp/pytest-of-USER/pytest-N``, 31 characters here); pytest-xdist adds ``popen-gwN/`` to it, which made 56 of
    those paths too long."""
    if config.option.basetemp is None and not hasattr(
        config, "workerinput"
    ):  # the controller's; the workers get theirs below it
        config.option.basetemp = config._dualarm_basetemp = tempfile.mkdtemp(prefix="dt-")  # type: ignore[attr-defined]


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """The base temporary directory made in :func:`pytest_configure` removed when every test passed (kept, to look into,
    otherwise)."""
    made = getattr(session.config, "_dualarm_basetemp", None)
    if made is not None and exitstatus == 0:
        shutil.rmtree(made, ignore_errors=True)


@pytest.fixture(scope="session", autouse=True)
def _tier_guard() -> Iterator[None]:
    """The tiers' guard (:mod:`tests.tiers`): a test not marked ``integration`` that connects to PyBullet, starts a Dask
    cluster or client, starts a process (but the numerics' C compiler) or a viewer, or records a run fails, naming the
    call."""
    with tiers.installed():
        yield


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[object]:
    """The test the guard judges: the one whose setup (its module and session fixtures included), call or teardown
    runs."""
    tiers.current = item
    try:
        return (yield)
    finally:
        tiers.current = None


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    """A unit test that gets a fixture which, set up for an earlier test, made a guarded call fails before its setup."""
    tiers.check_fixtures(item)


@pytest.hookimpl(wrapper=True)
def pytest_fixture_setup(fixturedef: pytest.FixtureDef, request: pytest.FixtureRequest) -> Iterator[object]:
    """The fixture the guard names when a test's setup makes a guarded call (its scope may share it with others)."""
    tiers.fixtures.append(tiers.fixture_key(fixturedef))
    try:
        return (yield)
    finally:
        tiers.fixtures.pop()


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> Iterator[pytest.TestReport]:
    """A phase in which a unit test made a guarded call fails, even if the code under test caught the guard's error."""
    report = yield
    violations = item.stash.get(tiers.VIOLATIONS, [])
    if violations and report.passed:
        report.outcome = "failed"
        report.longrepr = "\n".join(violations)
    violations.clear()
    return report


@pytest.fixture(scope="session", autouse=True)
def _click_command_built_once() -> Iterator[None]:
    """typer's ``CliRunner.invoke`` builds the app's Click command anew on every call (0.04 s; over the unit tier's 500
    invocations, a tenth of its time): built once per app here, as the ``dualarm`` script builds it once per process."""
    import typer.testing

    build = typer.testing._get_command
    typer.testing._get_command = functools.cache(build)
    try:
        yield
    finally:
        typer.testing._get_command = build


@pytest.fixture(scope="session")
def humanoid():
    from dualarm.model.robot import load_robot

    return load_robot(HUMANOID)


@pytest.fixture(scope="session")
def kuka_urdf() -> Path:
    """The KUKA LBR iiwa shipped in pybullet_data: a second, independent S-R-S arm."""
    import pybullet_data

    return Path(pybullet_data.getDataPath()) / "kuka_iiwa" / "model.urdf"


@pytest.fixture(scope="session")
def wheel_env(tmp_path_factory) -> Path:
    """A fresh virtual environment with dualarm installed from its wheel, built here. Its
    dependencies are reached through a .pth file pointing at this environment's site-packages (so
    nothing is downloaded); the checkout itself is not on its path."""
    root = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(root / "dist"),
            str(REPO),
        ],
        check=True,
        capture_output=True,
        timeout=600,
    )
    (wheel,) = (root / "dist").glob("dualarm-*.whl")
    venv = root / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=300)
    python = venv / "bin" / "python"
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "-q", "--no-deps", "--no-index", str(wheel)],
        check=True,
        capture_output=True,
        timeout=600,
    )
    site = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    (Path(site) / "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    return venv


def _shared_runs(tmp_path_factory, worker_id, kind: str, runs: dict[str, tuple]) -> dict[str, Path]:
    """Name -> the run directory of ``record_run(task, method, record=level)`` for each of ``runs``.

    Made once per test session: under pytest-xdist, the first worker to ask makes them in the
    session's base directory (under ``kind``), under a file lock, and the others read their
    directories from there (the pattern of pytest-xdist's documentation).
    """
    from filelock import FileLock

    from dualarm.run import record_run
    from dualarm.tasks import load_task

    def make(out: Path) -> dict[str, Path]:
        return {
            name: record_run(load_task(task, 1), method, out_dir=out, record=level).directory
            for name, (task, method, level) in runs.items()
        }

    if worker_id == "master":  # not under xdist
        return make(tmp_path_factory.mktemp(kind))
    shared = tmp_path_factory.getbasetemp().parent / kind
    made = shared / "runs.json"
    with FileLock(shared.with_suffix(".lock")):
        if not made.is_file():
            made.write_text(json.dumps({name: str(run) for name, run in make(shared).items()}))
    return {name: Path(run) for name, run in json.loads(made.read_text()).items()}


@pytest.fixture(scope="session")
def shipped_runs(tmp_path_factory, worker_id) -> dict[str, Path]:
    """Task name -> the run directory of a one-repetition run of that shipped task through every stage."""
    return _shared_runs(tmp_path_factory, worker_id, "shipped", {n: (n, m, "full") for n, m in SHIPPED.items()})


@pytest.fixture(scope="session")
def other_runs(tmp_path_factory, worker_id) -> dict[str, Path]:
    """Name -> the run directory of each of :data:`tests.helpers.OTHER_RUNS`: another robot, a lower record level."""
    return _shared_runs(tmp_path_factory, worker_id, "other", OTHER_RUNS)
