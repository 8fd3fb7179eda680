"""``dualarm consistency`` shows each method's orientation error beside the joint deviations, and marks a method that
solved positions only.

The orientation errors are checked against PyBullet's forward kinematics of the recorded IK samples
and scipy's rotations, the asked orientations read from the recorded reference.
"""

import json
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.contracts.verdict import Checks
from dualarm.record.readback import read_run
from dualarm.report.consistency import COLUMNS, POSITION_ONLY
from dualarm.sim.world import load_pybullet_robot
from tests.helpers import HUMANOID, TASKS

pytestmark = pytest.mark.integration

runner = CliRunner()


@pytest.fixture(scope="module")
def position_circle(tmp_path_factory):
    """The circle in the TV-GDD paper's position task space."""
    text = (TASKS / "circle.toml").read_text().replace('robot = "../robots/humanoid"', f'robot = "{HUMANOID}"')
    path = tmp_path_factory.mktemp("tasks") / "circle.toml"
    path.write_text(text + '\n[ik]\ntask_space = "position"\n')
    return path


def pybullet_orientation_errors(run: Path) -> np.ndarray:
    """Per IK sample of a circle run: the angle of R_asked^T R_reached of the left hand [rad], R_reached by PyBullet at
    the recorded joints (the others at circle.toml's ``initial``, read with tomllib), R_asked the recorded
    reference's."""
    data = read_run(run)
    samples, reference = data["/ik/sample"], data["/task/reference/left"]
    assert np.array_equal(samples["t"].to_numpy(), reference["t"].to_numpy())
    names = [c.split(".", 1)[1] for c in samples.columns if c.startswith("position.")]
    joints = samples[[f"position.{n}" for n in names]].to_numpy()
    asked = Rotation.from_quat(reference[[f"orientation.{a}" for a in "xyzw"]].to_numpy())
    initial = tomllib.loads((TASKS / "circle.toml").read_text())["initial"]
    angles = np.empty(len(samples))
    with load_pybullet_robot(HUMANOID / "humanoid.urdf") as sim:
        for k, row in enumerate(joints):
            q = {**initial, **dict(zip(names, row, strict=True))}
            sim.set_positions(list(q), list(q.values()))
            angles[k] = (asked[k].inv() * Rotation.from_matrix(sim.link_pose("left_hand")[:3, :3])).magnitude()
    return angles


def test_orientation_error_stands_beside_the_joint_deviations_and_position_only_is_marked(position_circle, tmp_path):
    """The table's orientation errors are PyBullet's. Position-only TV-GDD starts on the asked pose
    (circle.toml's ``initial`` is MC-Inverse's configuration at P0) and leaves it along the circle,
    by more than ten times the tolerance a pose-solving method is judged against (measured 0.72 rad)."""
    result = runner.invoke(
        app,
        ["consistency", str(position_circle), "--methods", "mc-inverse,tvgdd", "--reps", "2", "--out", str(tmp_path)],
        env={"COLUMNS": "250"},
    )
    assert result.exit_code == 0, result.output
    assert COLUMNS.index("orientation_error_max_rad") == COLUMNS.index("rep_arm_angle_deviation_max_rad") + 1
    table = pd.read_csv(tmp_path / "consistency.csv").set_index("method")
    for _method, row in table.iterrows():
        metrics = json.loads((Path(row["run"]) / "metrics.json").read_text())
        assert row["orientation_error_max_rad"] == metrics["ik.orientation_error_max_rad"]
        assert row["orientation_solved"] == metrics["ik.orientation_solved"]
    angles = {method: pybullet_orientation_errors(Path(row["run"])) for method, row in table.iterrows()}
    for method, angle in angles.items():
        assert table.loc[method, "orientation_error_max_rad"] == pytest.approx(angle.max(), abs=1e-6), method
    assert table.loc["mc-inverse", "orientation_solved"] == 1 and angles["mc-inverse"].max() < 1e-6
    assert table.loc["tvgdd", "orientation_solved"] == 0 and angles["tvgdd"][0] < 1e-5
    assert angles["tvgdd"].max() > 10 * Checks().ik_orientation_tolerance_rad
    markdown = (tmp_path / "consistency.md").read_text()
    assert f"| tvgdd ({POSITION_ONLY}) |" in markdown and "| mc-inverse |" in markdown
    (header,) = [line for line in markdown.splitlines() if line.startswith("| method |")]
    assert "| rep_arm_angle_deviation_max_rad | orientation_error_max_rad |" in header
    rows = [
        line.split("│") for line in result.stdout.splitlines() if line.startswith("│")
    ]  # rich wraps long cells over lines
    method_column = " ".join(cells[1].strip() for cells in rows)
    assert method_column == f"mc-inverse tvgdd ({POSITION_ONLY})"
    header = " ".join(line for line in result.stdout.splitlines() if line.startswith("┃"))
    assert all(word in header for word in ("orient.", "err", "max")), result.stdout  # however rich wraps it
