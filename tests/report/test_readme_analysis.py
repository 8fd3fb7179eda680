"""The scripted-analysis example of reports/README.md runs as documented and its consistency
table equals the ``ik.rep_*`` metrics each run computed from its solver's arrays."""

import json
import re
from pathlib import Path

import pytest

from dualarm.report.consistency import run_consistency
from tests.helpers import TASKS

pytestmark = pytest.mark.integration

README = Path(__file__).resolve().parents[2] / "reports" / "README.md"
DOCUMENTED_RUNS = 'Path("reports/reproduction/consistency/triangle/runs/triangle")'


def test_the_documented_consistency_table_equals_the_runs_metrics(tmp_path, capsys):
    # pybullet fails some samples of the triangle: the example must leave them out as the metric does.
    # A failed IK sample makes a run "violated" (README, "Verdicts and exit codes"); the runs still finish.
    result = run_consistency(TASKS / "triangle.toml", ["mc-inverse", "tvgdd", "pybullet"], tmp_path, repetitions=3)
    status = result.table.set_index("method")["status"]
    assert status["mc-inverse"] == status["tvgdd"] == "complete" and status["pybullet"] == "violated"
    code = re.search(r"## Scripted analysis.*?```python\n(.*?)```", README.read_text(), re.S).group(1)
    assert DOCUMENTED_RUNS in code and len(code.strip().splitlines()) <= 20
    namespace: dict = {}
    exec(code.replace(DOCUMENTED_RUNS, f'Path("{tmp_path / "runs" / "triangle"}")'), namespace)
    table = namespace["table"]
    assert "rep_joint_deviation_max_rad" in capsys.readouterr().out
    assert set(table.index) == {"mc-inverse", "tvgdd", "pybullet"}
    for run in (tmp_path / "runs" / "triangle").iterdir():
        metrics = json.loads((run / "metrics.json").read_text())
        method = json.loads((run / "manifest.json").read_text())["settings"]["ik"]["method"]
        for column in ("rep_joint_deviation_max_rad", "rep_arm_angle_deviation_max_rad"):
            assert table.loc[method, column] == pytest.approx(metrics[f"ik.{column}"], rel=1e-12, abs=1e-15), (
                method,
                column,
            )
        if method == "pybullet":
            assert metrics["ik.failures"] > 0  # failed samples are there to be left out
            violations = json.loads((run / "manifest.json").read_text())["violations"]
            assert any(
                v["check"] == "ik"
                and f"{int(metrics['ik.failures'])} of " in v["message"]
                and "samples failed" in v["message"]
                for v in violations
            ), violations
    assert table.loc["tvgdd", "rep_joint_deviation_max_rad"] > 1e-3  # the drift is there to be found
