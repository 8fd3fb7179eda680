"""dualarm: humanoid dual-arm motion papers as runnable, recorded, repeatable experiments.

``import dualarm`` gives a small API (everything in ``__all__``; modules load on first use, so the
import itself is quick):

Robots and tasks
    :func:`load_robot` (a directory or a shipped robot's name), :class:`Robot`, :func:`hand_pose`,
    :func:`to_arm_frame`; :func:`load_task` (a task file or a shipped task's name),
    :func:`task_from_dict` (the same keys from a dict or keyword arguments), :class:`Task`.

References:
    :func:`build_reference` (a task's hand motions), :meth:`CartesianReference.from_poses` (your own).
IK, each ``solve_*(robot, reference, q0, settings) -> JointPath``
    :func:`solve_tvgdd` (:class:`TvgddSettings`), :func:`solve_pinv`, :func:`solve_mc_inverse`
    and :func:`solve_sew` (:class:`ArmAngle`), :func:`solve_trac_ik`, :func:`solve_pybullet`, :func:`solve_dls_svd`,
    :func:`solve_ikfast_style`; one pose: :func:`mc_inverse` -> :class:`McSolution` (``.nearest``);
    consistency across repetitions: :func:`repetition_deviation`.
    Every method and planner is in the registry :data:`METHODS`.
Planning, timing, execution
    :func:`plan_task`, :func:`retime_path`, :func:`smooth_trajectory`, :func:`approach_trajectory`
    (from the initial configuration to a trajectory's start), :func:`execute_trajectory`.
The pipeline
    :func:`run_task` (in memory, products, metrics and the :class:`Verdict` -- complete, violated
    with each :class:`Violation`, judged against :class:`Checks` -- in a :class:`RunResult`), :func:`record_run`
    (MCAP + Rerun files), sinks :class:`Sink`, :class:`NullSink`, :class:`MetricsSink`,
    :class:`Recorder`; reading runs back into pandas: :func:`read_run`, :func:`read_runs`.
Studies (the MC-Inverse paper's open question: when, and how often, is repeated motion inconsistent?)
    :func:`load_study` (a spec file) -> :class:`StudySpec`; :func:`run_study` (every generated trial
    with every method, on Dask); :func:`read_study` (its rows, pandas);
    :func:`write_study_report` (P(inconsistent) per method and condition, from ``trials.parquet``).
Contracts between stages
    :class:`CartesianReference`, :class:`JointPath`, :class:`JointTrajectory`, :class:`ExecutionLog`.
Errors
    :class:`DualarmError` and its subclasses; :class:`InvalidArgumentError` is also a ``ValueError``.

The code lives in the repository's ``pipeline/dualarm/`` folder, in layers that import only from
those below them (DESIGN.md; checked by import-linter): the contracts (:mod:`dualarm.contracts`,
errors, arrays); the foundations (``numerics``, ``model``, ``sim``); the parts (``tasks``,
``paths``, ``ik``, ``describe``, ``plan``, ``retime``, ``smooth``, ``violations``, ``execute``,
``record``); the pipeline (``methods``, :mod:`dualarm.stages`, the driver :mod:`dualarm.run`);
the apps (``report``, ``reproduce``, ``study``, ``bench``, ``cli``).
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach_stub(__name__, __file__)
