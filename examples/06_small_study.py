"""A small study from Python: 6 generated trials, two methods, on a Dask LocalCluster; the rows in pandas, then the
report."""

import tempfile

import dualarm

spec = dualarm.StudySpec(
    name="small",
    trials=6,
    methods=("mc-inverse", "trac-ik"),
    repetitions=(2, 3),
    period_s=(3.0, 4.0),
    control_period_s=0.1,
)

if __name__ == "__main__":  # Dask starts its workers as new processes, which import this file
    with tempfile.TemporaryDirectory() as out:
        study = dualarm.run_study(spec, ".", out, workers=1)  # "." : where the spec's robot is relative to
        rows = study.results
        print(rows.groupby("method")[["inconsistent", "failed"]].mean())
        solved = rows[(rows["method"] == "mc-inverse") & ~rows["failed"]]
        print(
            f"mc-inverse, {len(solved)} trials solved: largest joint deviation between repetitions"
            f" {solved['ik.rep_joint_deviation_max_rad'].max():.1e} rad"
        )
        print("report:", dualarm.write_study_report(out).name)
