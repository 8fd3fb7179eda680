"""The Foxglove layout of a run names only what the run's ``run.mcap`` holds, read with the ``mcap`` reader.

That Foxglove Studio opens the layout, draws its 3D panel and accepts its plot paths is shown in
Studio itself by ``tests/record/test_viewer_foxglove.py``.
"""

import functools
import json
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from dualarm.contracts.run import ALL_STAGES
from dualarm.errors import InvalidArgumentError
from dualarm.record.foxglove_layout import STAGES, foxglove_layout
from dualarm.run import record_run
from dualarm.tasks import load_task
from tests.helpers import SHIPPED

LAYOUT_FILE = "foxglove-layout.json"


@functools.cache
def _recorded(mcap: Path) -> tuple[dict[str, list[dict]], set[str]]:
    """The run's JSON messages by topic (decoded with json), and every topic and /tf frame (protobuf) in it."""
    messages: dict[str, list[dict]] = {}
    frames: set[str] = set()
    with mcap.open("rb") as f:
        reader = make_reader(f)
        topics = {channel.topic for channel in reader.get_summary().channels.values()}
        for schema, channel, message in reader.iter_messages():
            if channel.message_encoding == "json":
                messages.setdefault(channel.topic, []).append(json.loads(message.data))
            elif channel.topic == "/tf":
                decoded = DecoderFactory().decoder_for(channel.message_encoding, schema)(message.data)
                frames |= {name for t in decoded.transforms for name in (t.parent_frame_id, t.child_frame_id)}
    return {**{t: [] for t in topics}, **messages}, frames


def _has_number(message: dict, fields: list[str]) -> bool:
    value: object = message
    for field in fields:
        value = value.get(field) if isinstance(value, dict) else None
    return isinstance(value, int | float) and not isinstance(value, bool)


def _missing(layout: dict, mcap: Path, environment: bool) -> list[str]:
    """What ``layout`` names that the run lacks: plot paths with no number in any message, 3D topics, the 3D frame."""
    messages, frames = _recorded(mcap)
    missing = []
    for panel, config in layout["configById"].items():
        if panel.startswith("Plot!"):
            for path in (p["value"] for p in config["paths"]):
                topic = max((t for t in messages if path.startswith(t + ".")), key=len, default=None)
                fields = path[len(topic) + 1 :].split(".") if topic else []
                if topic is None or not any(_has_number(m, fields) for m in messages[topic]):
                    missing.append(f"{panel}: {path}")
        elif panel.startswith("3D!"):
            absent = set(config["topics"]) - set(messages) - (set() if environment else {"/task/environment"})
            missing += [f"{panel}: topic {topic}" for topic in sorted(absent)]
            if config["followTf"] not in frames:
                missing.append(f"{panel}: frame {config['followTf']} on /tf")
    return missing


@pytest.mark.integration
@pytest.mark.parametrize("task", list(SHIPPED))
def test_every_path_of_a_shipped_runs_layout_is_in_its_mcap(shipped_runs, task):
    """The layout for the run's stages and hands: each plot path holds a number in some message, each 3D topic and its
    frame exist."""
    run = shipped_runs[task]
    spec = load_task(task, 1)
    layout = foxglove_layout(spec.robot, json.loads((run / "manifest.json").read_text())["stages"], spec.spec.hands)
    assert _missing(layout, run / "run.mcap", bool(spec.spec.environment)) == []


@pytest.mark.integration
@pytest.mark.parametrize("task", list(SHIPPED))
def test_each_shipped_run_carries_its_layout(shipped_runs, task):
    """The recorder writes foxglove-layout.json beside run.mcap, naming only what that run.mcap holds."""
    run = shipped_runs[task]
    assert (run / LAYOUT_FILE).is_file(), f"{run.name} has no {LAYOUT_FILE}"
    layout = json.loads((run / LAYOUT_FILE).read_text())
    assert _missing(layout, run / "run.mcap", bool(load_task(task, 1).spec.environment)) == []


@pytest.mark.integration
def test_a_path_and_ik_run_gets_panels_for_its_topics_only(tmp_path):
    task = load_task("triangle", 1)
    run = record_run(task, "mc-inverse", stages=("path", "ik"), out_dir=tmp_path)
    layout = foxglove_layout(task.robot, ("path", "ik"), task.spec.hands)
    assert _missing(layout, run.directory / "run.mcap", False) == []
    assert "/execute" not in json.dumps(layout)
    full = foxglove_layout(task.robot, ("path", "ik", "retime", "smooth", "execute"), task.spec.hands)
    assert "Plot!hand-error: /execute/sample.hand_error_m.left" in _missing(
        full, run.directory / "run.mcap", False
    )  # the check can fail
    paths = [p["value"] for c in layout["configById"].values() for p in c.get("paths", [])]
    assert "/ik/sample.arm_angle_rad.left" in paths and "/ik/sample.hand_error_m.left" in paths
    assert "/ik/hand_path" in layout["configById"]["3D!dualarm"]["topics"]


def test_joints_outside_the_arms_get_a_plot_of_their_own(humanoid):
    """A free waist: its joints, given as the run's joints, are plotted together; the arms' as before."""
    waist = humanoid.chain("waist").joint_names
    layout = foxglove_layout(
        humanoid,
        ("path", "plan", "retime", "smooth", "execute"),
        ("left",),
        (*humanoid.hand_chain("left").joint_names, *waist),
    )
    plotted = {
        panel: [p["value"].rsplit(".", 1)[1] for p in config["paths"]]
        for panel, config in layout["configById"].items()
        if panel.startswith("Plot!joints")
    }
    assert plotted == {
        "Plot!joints-left_arm": list(humanoid.hand_chain("left").joint_names),
        "Plot!joints-waist": list(waist),
    }


def test_the_stages_are_the_runs():
    assert STAGES == ALL_STAGES


@pytest.mark.parametrize(
    ("stages", "hands", "joints", "argument"),
    [
        (("path", "fly"), ("left",), None, "stages"),
        (("path",), ("tail",), None, "hands"),
        (("path",), ("left",), ("nope",), "joint_names"),
    ],
)
def test_a_name_the_robot_or_run_cannot_have_is_refused(humanoid, stages, hands, joints, argument):
    with pytest.raises(InvalidArgumentError, match=f"^{argument}: unknown name") as raised:
        foxglove_layout(humanoid, stages, hands, joints)
    assert raised.value.argument == argument
