"""`--ik sew` along a path on the offset humanoid (7R arms, not S-R-S), the SEW angle chosen by the `auto` search: the
shipped circle on another robot repeats exactly, as PyBullet measures it."""

import numpy as np
import pytest

from dualarm.ik.analytic.sew_path import settings_for, sew_angle_of
from dualarm.model.sew import sew_chain
from dualarm.report.consistency import run_consistency
from dualarm.tasks import load_task
from tests.helpers import OFFSET, TASKS, pybullet_urdf

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def circle(tmp_path_factory):
    return run_consistency(
        TASKS / "circle.toml",
        ["sew", "dls-svd"],
        tmp_path_factory.mktemp("sew") / "consistency",
        repetitions=2,
        robot=OFFSET,
    )


def test_auto_sew_repeats_the_circle_on_the_offset_humanoid(circle):
    """2 circles on robots/humanoid_offset, [arm_angle] mode auto: sew completes (every check of the IK stage, joint
    velocities included, passes) and its joints repeat to 1e-9 rad; DLS-SVD's do not (more than 1e-3 rad)."""
    table = circle.table.set_index("method")
    assert table.loc["sew", "status"] == "complete"
    assert table.loc["sew", "rep_joint_deviation_max_rad"] <= 1e-9
    assert table.loc["dls-svd", "rep_joint_deviation_max_rad"] > 1e-3


def test_the_sew_angle_repeats_as_pybullet_measures_it(circle):
    """The SEW angle of the recorded joints, S, E and W carried by PyBullet's link frames (E fixed in the upper arm, W
    in the wrist pitch link), is the same at the same time of each repetition (1e-6: PyBullet's float32)."""
    from dualarm.contracts.reference import first_repetition_index
    from dualarm.record.readback import read_run

    run = read_run(circle.table.set_index("method").loc["sew", "run"])
    task = load_task(TASKS / "circle.toml", 2, OFFSET)
    chain = task.robot.hand_chain("left")
    arm, sew = sew_chain(chain), sew_angle_of(settings_for(task))
    samples = run["/ik/sample"]
    q = samples[[f"position.{n}" for n in chain.joint_names]].to_numpy()
    with pybullet_urdf(OFFSET / "humanoid_offset.urdf") as sim:
        base = sim.frame(chain.base)

        def frames(row: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            sim.set(chain.joint_names, row)
            return np.linalg.inv(base) @ sim.frame("left_upper_arm"), np.linalg.inv(base) @ sim.frame(
                "left_wrist_pitch_link"
            )

        zero3, zero6 = frames(np.zeros(7))
        e_local, w_local = (
            np.linalg.inv(zero3) @ np.append(arm.elbow, 1.0),
            np.linalg.inv(zero6) @ np.append(arm.wrist, 1.0),
        )
        angles = []
        for row in q:
            T3, T6 = frames(row)
            angles.append(float(sew.angle(arm.shoulder, (T3 @ e_local)[:3], (T6 @ w_local)[:3])))
    angles = np.array(angles)
    same_time = first_repetition_index(samples["t"].to_numpy(), samples["rep"].to_numpy(), task.spec.control_period_s)
    assert samples["rep"].max() == 1
    assert np.abs(np.angle(np.exp(1j * (angles - angles[same_time])))).max() < 1e-6
