"""The Franka Panda (robots/panda, one arm, not S-R-S) through every stage with the methods that do not need S-R-S,
checked against PyBullet on pybullet_data's own panda.urdf."""

from pathlib import Path

import numpy as np
import pybullet as pb
import pybullet_data
import pytest

from dualarm.model.robot import load_robot
from dualarm.record.readback import read_run
from dualarm.run import record_run

HERE = Path(__file__).parent
PANDA = HERE.parents[1] / "robots" / "panda"
TASK = HERE / "panda_triangle.toml"
ORIGINAL = Path(pybullet_data.getDataPath()) / "franka_panda" / "panda.urdf"
ARM = tuple(f"panda_joint{i}" for i in range(1, 8))


class OriginalPanda:
    """pybullet_data's own panda.urdf in a DIRECT PyBullet client: forward kinematics of the grasp target."""

    def __init__(self) -> None:
        self.client = pb.connect(pb.DIRECT)
        self.body = pb.loadURDF(str(ORIGINAL), useFixedBase=True, physicsClientId=self.client)
        infos = [
            pb.getJointInfo(self.body, i, physicsClientId=self.client)
            for i in range(pb.getNumJoints(self.body, physicsClientId=self.client))
        ]
        self.joint = {info[1].decode(): i for i, info in enumerate(infos)}
        self.link = {info[12].decode(): i for i, info in enumerate(infos)}

    def hand(self, q: np.ndarray) -> np.ndarray:
        """The grasp target's position [m] at arm configurations q (N, 7) [rad]; (N, 3)."""
        out = []
        for row in np.atleast_2d(q):
            for name, value in zip(ARM, row, strict=True):
                pb.resetJointState(self.body, self.joint[name], float(value), physicsClientId=self.client)
            out.append(
                pb.getLinkState(
                    self.body,
                    self.link["panda_grasptarget"],
                    computeForwardKinematics=True,
                    physicsClientId=self.client,
                )[4]
            )
        return np.array(out)

    def close(self) -> None:
        pb.disconnect(self.client)


@pytest.fixture(scope="module")
def original():
    sim = OriginalPanda()
    yield sim
    sim.close()


@pytest.mark.integration
def test_the_copied_urdf_moves_as_pybullet_datas(original):
    from dualarm.model.kinematics import hand_pose

    robot = load_robot(PANDA)
    lower, upper = robot.lower_upper(ARM)
    q = np.random.default_rng(3).uniform(lower, upper, (20, 7))
    ours = np.array([hand_pose(robot, "right", dict(zip(ARM, row, strict=True)))[:3, 3] for row in q])
    assert np.abs(ours - original.hand(q)).max() < 1e-6  # PyBullet computes in single precision here (2.8e-8 m seen)


def test_ready_is_inside_the_limits_and_the_datasheet_limits_are_read():
    robot = load_robot(PANDA)
    lower, upper = robot.lower_upper(ARM)
    ready = np.array([robot.home("ready")[n] for n in ARM])
    assert ((lower < ready) & (ready < upper)).all()  # the arm strictly inside (the fingers open, at their limit)
    # Franka's datasheet, as robot.toml cites it
    assert robot.limit_array("acceleration", ARM).tolist() == [15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0]
    assert robot.limit_array("jerk", ARM).tolist() == [7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0]


@pytest.mark.integration
@pytest.mark.parametrize("method", ["tvgdd", "dls-svd", "sew"])
def test_every_stage_runs_and_the_hand_follows_the_path(method, original, tmp_path):
    result = record_run(TASK, method, out_dir=tmp_path, command=["test"])
    run = read_run(result.directory)
    assert run.status in ("complete", "violated")
    if run.status == "violated":
        assert run.violations  # an honest verdict names its reason
    for stage in ("path", "ik", "retime", "smooth", "execute"):
        assert any(k.startswith(f"{stage}.") for k in run.metrics), stage
    sample = run["/ik/sample"]
    assert (
        "ik.rep_arm_angle_deviation_max_rad" in run.metrics and "arm_angle_rad.right" in sample
    )  # the Panda's arm angle is its SEW angle
    q = sample[[f"position.{n}" for n in ARM]].to_numpy()
    asked = result.reference.hands["right"].position
    reached = original.hand(q)  # PyBullet's FK of pybullet_data's URDF, not ours
    assert np.linalg.norm(reached - asked, axis=1).max() < 1e-3
    # the simulated arm's last measured configuration puts the hand at the path's end, by PyBullet's FK again
    log = result.execution
    end = original.hand(np.array([[log.q[-1, list(log.joint_names).index(n)] for n in ARM]]))[0]
    assert np.linalg.norm(end - asked[-1]) < 5e-3
