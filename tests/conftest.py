"""Shared fixtures: the repository's robot and task directories, and PyBullet's own view of a URDF."""

import contextlib
import json
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
HUMANOID = REPO / "robots" / "humanoid"
OFFSET = REPO / "robots" / "humanoid_offset"
TASKS = REPO / "tasks"


def pytest_configure(config: pytest.Config) -> None:
    """A short base temporary directory, made for this run: a one-line message quotes a long path shortened (:func:`dualarm.errors.excerpt`), and the tests match whole paths, written for pytest's own base (``/tmp/pytest-of-USER/pytest-N``, 31 characters here); pytest-xdist adds ``popen-gwN/`` to it, which made 56 of those paths too long."""
    if config.option.basetemp is None and not hasattr(
        config, "workerinput"
    ):  # the controller's; the workers get theirs below it
        config.option.basetemp = config._dualarm_basetemp = tempfile.mkdtemp(prefix="dt-")  # type: ignore[attr-defined]


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """The base temporary directory made in :func:`pytest_configure` removed when every test passed (kept, to look into, otherwise)."""
    made = getattr(session.config, "_dualarm_basetemp", None)
    if made is not None and exitstatus == 0:
        shutil.rmtree(made, ignore_errors=True)


def wrist_offset_robot(directory: Path) -> Path:
    """Write into ``directory`` the offset humanoid with its left wrist pitch axis moved 2 cm off the forearm roll axis: a 7R arm of no SEW family (the right arm untouched). Returns ``directory``."""
    text = (OFFSET / "humanoid_offset.urdf").read_text()
    origin = text.index('<origin xyz="0 0 0"', text.index('<joint name="left_wrist_pitch"'))
    (directory / "offset_wrist.urdf").write_text(
        text[:origin] + '<origin xyz="0.02 0 0"' + text[origin + len('<origin xyz="0 0 0"') :]
    )
    (directory / "robot.toml").write_text(
        (OFFSET / "robot.toml").read_text().replace('urdf = "humanoid_offset.urdf"', 'urdf = "offset_wrist.urdf"')
    )
    return directory


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


def still_path_fields(
    n: int, *, joint: str = "a", hand: str = "left", method: str = "x", period_s: float = 0.01, **fields
) -> dict:
    """The fields of a one-joint, one-hand :class:`~dualarm.contracts.joint_path.JointPath` of ``n`` samples at rest at 0, every sample solved; ``fields`` replace any of them."""
    import numpy as np

    return {
        "method": method,
        "joint_names": (joint,),
        "t": np.arange(n) * period_s,
        "rep": np.zeros(n, int),
        "q": np.zeros((n, 1)),
        "qd": np.zeros((n, 1)),
        "status": np.zeros(n, int),
        "solve_time_s": np.zeros(n),
        "hand_error_m": np.zeros((n, 1)),
        "hands": (hand,),
        **fields,
    }


#: Each shipped task and the method it is reproduced with, for the tests that open runs in the viewers.
SHIPPED = {
    "triangle": "mc-inverse",
    "circle": "mc-inverse",
    "ball_game": "tvgdd",
    "carry_box": "mc-inverse",
    "bowl_grasp": "mcikrrt",
}


@pytest.fixture(scope="session")
def shipped_runs(tmp_path_factory, worker_id) -> dict[str, Path]:
    """Task name -> the run directory of a one-repetition run of that shipped task through every stage.

    Made once per test session: under pytest-xdist, the first worker to ask makes them in the
    session's base directory, under a file lock, and the others read their directories from there
    (the pattern of pytest-xdist's documentation).
    """
    from filelock import FileLock

    from dualarm.run import record_run
    from dualarm.tasks import load_task

    def make(out: Path) -> dict[str, Path]:
        return {name: record_run(load_task(name, 1), method, out_dir=out).directory for name, method in SHIPPED.items()}

    if worker_id == "master":  # not under xdist
        return make(tmp_path_factory.mktemp("shipped"))
    shared = tmp_path_factory.getbasetemp().parent / "shipped"
    made = shared / "runs.json"
    with FileLock(shared.with_suffix(".lock")):
        if not made.is_file():
            made.write_text(json.dumps({name: str(run) for name, run in make(shared).items()}))
    return {name: Path(run) for name, run in json.loads(made.read_text()).items()}


@dataclass
class PyBulletURDF:
    """A URDF loaded in its own DIRECT PyBullet client (fixed base at the origin): an independent forward kinematics for tests."""

    client: int
    body: int
    joint: dict[str, int]
    link: dict[str, int]

    def set(self, names: Sequence[str], values: Sequence[float]) -> None:
        """Put joints ``names`` at ``values`` [rad]."""
        import pybullet as pb

        for name, value in zip(names, values):
            pb.resetJointState(self.body, self.joint[name], float(value), physicsClientId=self.client)

    def frame(self, link: str) -> np.ndarray:
        """The URDF frame of ``link`` (not a root link) in the world, (4, 4) [m]; PyBullet computes in single precision."""
        import pybullet as pb

        state = pb.getLinkState(self.body, self.link[link], computeForwardKinematics=True, physicsClientId=self.client)
        T = np.eye(4)
        T[:3, :3] = np.reshape(pb.getMatrixFromQuaternion(state[5]), (3, 3))
        T[:3, 3] = state[4]
        return T


@contextlib.contextmanager
def pybullet_urdf(path: Path) -> Iterator[PyBulletURDF]:
    """``path`` loaded in a DIRECT PyBullet client, joints and child links by name; the client is closed after."""
    import pybullet as pb

    client = pb.connect(pb.DIRECT)
    try:
        body = pb.loadURDF(str(path), useFixedBase=True, physicsClientId=client)
        infos = [
            pb.getJointInfo(body, i, physicsClientId=client)
            for i in range(pb.getNumJoints(body, physicsClientId=client))
        ]
        yield PyBulletURDF(
            client,
            body,
            {info[1].decode(): i for i, info in enumerate(infos)},
            {info[12].decode(): i for i, info in enumerate(infos)},
        )
    finally:
        pb.disconnect(client)
