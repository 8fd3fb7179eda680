"""A task from a plain dict, through every stage in memory (no files): IK, retime, smooth, execute."""

import dualarm

task = dualarm.task_from_dict(
    name="lift",
    robot="humanoid",
    control_period_s=0.01,
    repetitions=2,
    initial="ready",
    waypoints={"A": {"position": [0.30, 0.27, 1.00], "rpy": [-1.572, -0.975, -1.570]}},  # [m], [rad]
    start={"left": "A"},
    moves=[{"duration_s": 1.0, "left": {"by": [0.0, 0.0, 0.08]}}, {"duration_s": 1.0, "left": {"to": "A"}}],
)
sink = dualarm.MetricsSink()
result = dualarm.run_task(task, "mc-inverse", sink=sink)
for stage, seconds in sink.stage_seconds.items():
    print(f"{stage:8s} {seconds:6.2f} s")
print(
    "executed for",
    result.execution.t[-1],
    "s; hand tracking error",
    f"{result.metrics['execute.tracking_error_max_m']:.1e} m",
)
