"""Plan the shipped bowl grasp with MCIKRRT (Li & Liang), once, and look at the plan."""

import dualarm

task = dualarm.load_task("bowl_grasp")  # a shipped task, or a path to a task file
result = dualarm.plan_task(task, "mcikrrt", seed=0)
print("found a path:", result.success, f"in {result.planning_time_s * 1e3:.0f} ms")
print(
    f"{len(result.path)} waypoints, {result.path_length_rad:.2f} rad long, {result.collision_checks} collision checks"
)
