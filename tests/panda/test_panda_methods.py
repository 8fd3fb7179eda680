"""The methods registry on a robot that is not S-R-S: the Panda runs every method but those that need S-R-S, which are
refused in one line."""

from pathlib import Path

import numpy as np
import pybullet as pb
import pybullet_data
import pytest
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.errors import NotSRSError
from dualarm.methods import IK_METHODS, METHODS, suited_methods
from dualarm.model.robot import load_robot
from dualarm.run import build_stages
from dualarm.tasks import load_task
from tests.helpers import HUMANOID

HERE = Path(__file__).parent
TASK = HERE / "panda_triangle.toml"
PANDA = HERE.parents[1] / "robots" / "panda"
runner = CliRunner()


def _axes_6_7_distance_m() -> float:
    """The distance between the axes of panda_joint6 and panda_joint7 at a random configuration, by PyBullet on
    pybullet_data's panda.urdf (in an S-R-S wrist they meet)."""
    client = pb.connect(pb.DIRECT)
    try:
        body = pb.loadURDF(
            str(Path(pybullet_data.getDataPath()) / "franka_panda" / "panda.urdf"),
            useFixedBase=True,
            physicsClientId=client,
        )
        for i, value in enumerate(np.random.default_rng(1).uniform(-0.5, 0.5, 7)):
            pb.resetJointState(
                body, i, value - (1.5 if i == 3 else 0.0), physicsClientId=client
            )  # joint 4 inside its limits
        axes = []
        for i in (5, 6):  # the joint's child link frame is its joint frame; every Panda axis is that frame's z
            state = pb.getLinkState(body, i, computeForwardKinematics=True, physicsClientId=client)
            axes.append((np.array(state[4]), np.array(pb.getMatrixFromQuaternion(state[5])).reshape(3, 3)[:, 2]))
    finally:
        pb.disconnect(client)
    (p1, d1), (p2, d2) = axes
    n = np.cross(d1, d2)
    return (
        float(abs(np.dot(p2 - p1, n)) / np.linalg.norm(n))
        if np.linalg.norm(n) > 1e-9
        else float(np.linalg.norm(np.cross(p2 - p1, d1)))
    )


@pytest.mark.integration
def test_the_panda_wrist_is_not_spherical():
    assert abs(_axes_6_7_distance_m() - 0.088) < 1e-6  # the flange offset of the URDF


def test_suited_methods_are_those_that_do_not_need_srs():
    panda, humanoid = load_robot(PANDA), load_robot(HUMANOID)
    assert suited_methods(panda, ["right"]) == tuple(n for n in IK_METHODS if not METHODS[n].needs_srs)
    assert {"mc-inverse", "ikfast-style"}.isdisjoint(suited_methods(panda, ["right"]))
    assert "sew" in suited_methods(panda, ["right"])  # the Panda is of the SEW solver's family
    assert (
        suited_methods(humanoid, ["left", "right"]) == IK_METHODS
    )  # an S-R-S arm is of the SEW solver's R-2R-R-3R family too


@pytest.mark.parametrize("method", ["mc-inverse", "ikfast-style"])
def test_a_method_that_needs_srs_is_refused_naming_method_chain_and_joints(method):
    task = load_task(TASK)
    with pytest.raises(NotSRSError) as caught:
        build_stages(task, method)
    message = str(caught.value)
    assert "\n" not in message and message.startswith(f"{method} needs S-R-S arms")
    assert "chain 'arm'" in message and "panda_joint5, panda_joint6, panda_joint7" in message
    assert "tvgdd" in message and "mc-inverse" not in message.split("methods that run on it:")[1]


@pytest.mark.parametrize("method", ["tvgdd", "pinv", "dls-svd", "trac-ik", "pybullet", "sew"])
def test_every_method_that_does_not_need_srs_is_built(method):
    stages = build_stages(load_task(TASK), method, stages=("path", "ik"))
    assert [s.name for s in stages] == ["path", "ik"]


def test_the_cli_refuses_mc_inverse_on_the_panda_in_one_line(tmp_path):
    result = runner.invoke(app, ["run", str(TASK), "--ik", "mc-inverse", "--out", str(tmp_path)])
    assert result.exit_code == 2
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and "mc-inverse needs S-R-S arms" in lines[0] and "panda_joint5" in lines[0]
    assert not any(tmp_path.iterdir())  # refused before anything was written
