"""Record a run of a shipped task and read it back into pandas, as reports do."""

import dualarm

run = dualarm.record_run("triangle", "mc-inverse", stages=("path", "ik"), out_dir="recordings")
print("recorded", run.directory)

data = dualarm.read_run(run.directory)
samples = data["/ik/sample"]  # a DataFrame: t, rep, stage and one column per field
per_rep = samples.groupby("rep")["arm_angle_rad.left"].agg(["min", "max"])
print(per_rep)
print("largest joint change between repetitions [rad]:", data.metrics["ik.rep_joint_deviation_max_rad"])
