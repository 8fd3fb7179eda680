"""``dualarm consistency`` on a robot that is not S-R-S (the Panda): a table and figures, its arm angle the SEW angle,
no KeyError."""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from dualarm.cli import app
from dualarm.errors import NotSRSError
from dualarm.ik.analytic.sew import SewAngle
from dualarm.model.robot import load_robot
from dualarm.model.sew import sew_chain
from dualarm.record.readback import read_run
from dualarm.report import figures
from dualarm.report.consistency import run_consistency

TASK = Path(__file__).parents[1] / "panda" / "panda_triangle.toml"
PANDA = Path(__file__).parents[2] / "robots" / "panda"
ARM = [f"panda_joint{i}" for i in range(1, 8)]
runner = CliRunner()


@pytest.mark.integration
def test_consistency_on_the_panda_with_two_methods_and_two_repetitions(tmp_path):
    result = runner.invoke(
        app, ["consistency", str(TASK), "--methods", "tvgdd,dls-svd", "--reps", "2", "--out", str(tmp_path)]
    )
    assert result.exit_code in (0, 3), result.output
    table = pd.read_csv(tmp_path / "consistency.csv")
    assert list(table["method"]) == ["tvgdd", "dls-svd"] and set(table["status"]) <= {"complete", "violated"}
    assert (tmp_path / "joints_right.png").stat().st_size > 0 and (tmp_path / "arm_angle.png").stat().st_size > 0
    sew = SewAngle(
        reference=(0.0, 0.0, 1.0), singular=(0.0, 0.0, -1.0)
    )  # the task's vertical: the stereographic SEW angle
    arm = sew_chain(load_robot(PANDA).hand_chain("right"))
    for (
        _,
        row,
    ) in (
        table.iterrows()
    ):  # the table's deviations are the runs' own joints and their SEW angles, repetition 1 against 0
        sample = read_run(Path(row["run"]))["/ik/sample"]
        q = sample[[f"position.{n}" for n in ARM]].to_numpy()
        rep = sample["rep"].to_numpy()
        first, second = q[rep == 0], q[rep == 1]
        assert len(first) == len(second) + 1  # rep 0 holds the start sample
        assert np.isclose(row["rep_joint_deviation_max_rad"], np.abs(second - first[1:]).max())
        psi = sew.angle(*arm.points(q))
        assert np.abs(sample["arm_angle_rad.right"].to_numpy() - psi).max() < 1e-9
        assert np.isclose(
            row["rep_arm_angle_deviation_max_rad"],
            np.abs(np.angle(np.exp(1j * (psi[rep == 1] - psi[rep == 0][1:])))).max(),
        )


def test_a_method_that_needs_srs_is_refused_before_anything_runs(tmp_path):
    with pytest.raises(NotSRSError, match="mc-inverse needs S-R-S arms"):
        run_consistency(TASK, ["tvgdd", "mc-inverse"], tmp_path / "out", repetitions=2)
    assert not (tmp_path / "out").exists()


def test_the_arm_angle_figure_draws_a_sample_without_one(tmp_path):
    sample = pd.DataFrame(
        {"t": np.arange(4) * 0.01, "rep": [0, 0, 1, 1], "status": 0, "arm_angle_rad.left": [0.1, 0.2, 0.1, 0.2]}
    )
    path = figures.arm_angle_per_repetition(
        {"a": sample}, ["left", "right"], "t", tmp_path / "psi.png"
    )  # the right arm has none
    assert path.stat().st_size > 0
