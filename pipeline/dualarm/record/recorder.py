"""The recorder: each stage hands it its product once.

It writes ``run.mcap``, ``run.rrd`` and ``foxglove-layout.json``.

A :class:`~dualarm.record.sink.Tee` of the MCAP sink (:mod:`dualarm.record.mcap_sink`: ``run.mcap``
for Foxglove, and its layout) and the Rerun sink (:mod:`dualarm.record.rerun_sink`: ``run.rrd`` and
its blueprint); each writes its own file, in the order the stages hand their products.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from dualarm.contracts.run import ALL_STAGES
from dualarm.model.robot import Robot
from dualarm.record.mcap_sink import McapSink
from dualarm.record.rerun_sink import RerunSink
from dualarm.record.sink import Tee


class Recorder(Tee):
    """The sink that writes one run's ``run.mcap`` and ``run.rrd`` into ``directory``.

    Args:
        directory: the (temporary) run directory.
        run_id: the run's id (also the Rerun recording id).
        robot: the robot, for /tf and the URDF.
        attachments: file name -> text, stored in the MCAP (task file, robot.toml, URDF).
        stages: the stages recorded (the others' products are dropped; for the layout the run
            opens on and the robot on ``/tf``).
        on_begin: called with each stage's name as it begins.
    """

    def __init__(
        self,
        directory: Path,
        run_id: str,
        robot: Robot,
        attachments: Mapping[str, str],
        stages: Sequence[str] = ALL_STAGES,
        on_begin: Callable[[str], None] | None = None,
    ) -> None:
        super().__init__(
            McapSink(directory, robot, attachments, stages),
            RerunSink(directory, run_id, robot, stages),
            on_begin=on_begin,
        )
