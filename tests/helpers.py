"""Helpers the tests import: the repository's robot and task directories, small builders and PyBullet's own FK.

A plain module (``from tests.helpers import ...``); ``tests/conftest.py`` keeps the fixtures and hooks alone.
"""

import contextlib
import subprocess
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
HUMANOID = REPO / "robots" / "humanoid"
OFFSET = REPO / "robots" / "humanoid_offset"
TASKS = REPO / "tasks"


def dualarm_subprocess(args: Sequence[str], timeout: float = 300) -> subprocess.CompletedProcess:
    """``dualarm ARGS`` in a fresh interpreter (the real stderr, text); the timeout turns a hang into a failure."""
    return subprocess.run(
        [sys.executable, "-c", "from dualarm.cli import app; app()", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def wrist_offset_robot(directory: Path) -> Path:
    """Write into ``directory`` the offset humanoid with its left wrist pitch axis moved 2 cm off the forearm roll axis:
    a 7R arm of no SEW family (the right arm untouched). Returns ``directory``."""
    text = (OFFSET / "humanoid_offset.urdf").read_text()
    origin = text.index('<origin xyz="0 0 0"', text.index('<joint name="left_wrist_pitch"'))
    (directory / "offset_wrist.urdf").write_text(
        text[:origin] + '<origin xyz="0.02 0 0"' + text[origin + len('<origin xyz="0 0 0"') :]
    )
    (directory / "robot.toml").write_text(
        (OFFSET / "robot.toml").read_text().replace('urdf = "humanoid_offset.urdf"', 'urdf = "offset_wrist.urdf"')
    )
    return directory


def still_path_fields(
    n: int, *, joint: str = "a", hand: str = "left", method: str = "x", period_s: float = 0.01, **fields
) -> dict:
    """The fields of a one-joint, one-hand :class:`~dualarm.contracts.joint_path.JointPath` of ``n`` samples at rest at
    0, every sample solved; ``fields`` replace any of them."""
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
#: Runs the viewer tests open besides the shipped ones: name -> (task file, method, record level). A robot whose URDF
#: names meshes by relative paths (the Panda), and a run recorded up to the IK only.
OTHER_RUNS = {
    "panda_triangle": (str(REPO / "tests" / "panda" / "panda_triangle.toml"), "sew", "full"),
    "triangle_ik": ("triangle", "mc-inverse", "ik"),
}


@dataclass
class PyBulletURDF:
    """A URDF loaded in its own DIRECT PyBullet client (fixed base at the origin): an independent forward kinematics for
    tests."""

    client: int
    body: int
    joint: dict[str, int]
    link: dict[str, int]

    def set(self, names: Sequence[str], values: Sequence[float]) -> None:
        """Put joints ``names`` at ``values`` [rad]."""
        import pybullet as pb

        for name, value in zip(names, values, strict=True):
            pb.resetJointState(self.body, self.joint[name], float(value), physicsClientId=self.client)

    def frame(self, link: str) -> np.ndarray:
        """The URDF frame of ``link`` (not a root link) in the world, (4, 4) [m]; PyBullet computes in single
        precision."""
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
