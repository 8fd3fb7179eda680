"""``run.mcap`` of every shipped task opened with Foxglove Studio 1.48.0's own code (``viewers/foxglove``).

Two checks, both running the code of ``@foxglove/studio-base`` 1.48.0 from npm (the last open-source
Foxglove Studio; Lichtblick continues it with the same parsers):

- in Node (``check-mcap.cjs``, seconds): Studio's channel parser, data source and message decoding on
  every channel, its URDF parser on ``/robot_description``, and its message path code on every plot
  path of the run's layout;
- in headless Chromium (``open-in-studio.cjs``, ~25 s a run): the whole Studio app opens one run per
  robot kind (:data:`STUDIO`) with the run's layout; what it shows is read back: its Problems tab, the
  URDF layer's parse error, the 3D panel's layer errors, and screenshots of the 3D panel with the URDF
  layer on and off. The other runs of that robot are read by the Node check's run of the same parsers.

Without Node, the npm install or Chromium the tests are skipped, saying what to run.
"""

import json
import os
import shutil
import subprocess
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from dualarm.model.robot import load_robot
from dualarm.record.foxglove_layout import message_path
from tests.helpers import OTHER_RUNS, REPO, SHIPPED

FOXGLOVE = REPO / "viewers" / "foxglove"
NODE = shutil.which("node")
CHROMIUM = Path(os.environ.get("CHROMIUM", "/usr/bin/chromium"))
LAYOUT_FILE = "foxglove-layout.json"
#: Robot pixels must stay this far from the 3D panel's edges (the whole robot in view) [px].
MARGIN_PX = 4
#: Two screenshots' pixels match when every RGB channel is this close, allowing a shift of one pixel.
TOLERANCE = 24
#: The 3D panels' screenshots are compared without their outermost pixels [px].
BORDER_PX = 2
#: Robot kind -> the shipped task whose run the whole Studio app opens: the last of that robot's in :data:`SHIPPED`
#: (for the humanoid the bowl grasp, whose run holds the most: both hands, the task's objects, the free waist, the plan
#: stage). Studio opening more runs of the same robot would repeat the same checks on the same URDF.
STUDIO = {Path(tomllib.loads((REPO / "tasks" / f"{task}.toml").read_text())["robot"]).name: task for task in SHIPPED}
#: Every run the Node check reads: the shipped tasks' and :data:`OTHER_RUNS` (the Panda, whose URDF names meshes by
#: relative paths, and a run recorded up to the IK); the whole Studio app opens those of :data:`STUDIO` and the others.
RUNS = [*SHIPPED, *OTHER_RUNS]
OPENED = [*STUDIO.values(), "carry_box", *OTHER_RUNS]  # carry_box: the box its hands carry
#: The runs opened as a user does who opens the file, then imports its layout (a humanoid and a Panda run).
IMPORTED = ["carry_box", "panda_triangle"]

pytestmark = [
    pytest.mark.integration,
    pytest.mark.skipif(
        NODE is None or not (FOXGLOVE / "node_modules" / "@foxglove" / "studio-base" / "package.json").is_file(),
        reason="the Foxglove tests need Node.js >= 20 and its packages: npm ci --prefix viewers/foxglove",
    ),
]
needs_chromium = pytest.mark.skipif(
    not CHROMIUM.is_file(), reason=f"the Foxglove browser tests need Chromium at {CHROMIUM}: apt-get install chromium"
)


def _node(script: str, *args: str, timeout_s: float) -> list[dict]:
    """Run a harness script; its JSON lines. Exit code 1 means findings (asserted by the tests), 2 the harness
    failed."""
    done = subprocess.run(
        [str(NODE), str(FOXGLOVE / script), *args], capture_output=True, text=True, timeout=timeout_s, check=False
    )
    assert done.returncode in (0, 1), f"{script} failed:\n{done.stderr[-3000:]}"
    return [json.loads(line) for line in done.stdout.splitlines()]


def _layout_args(run: Path) -> list[str]:
    return ["--layout", str(run / LAYOUT_FILE)] if (run / LAYOUT_FILE).is_file() else []


@pytest.fixture(scope="module")
def runs(shipped_runs, other_runs) -> dict[str, Path]:
    """Name -> run directory, for every name of :data:`RUNS`."""
    return {**shipped_runs, **other_runs}


@pytest.fixture(scope="module")
def bad_run(tmp_path_factory, shipped_runs) -> Path:
    """A negative control: the triangle run (linked) with a layout whose plot path names a joint the run has not and
    whose 3D panel follows a frame it lacks."""
    run = tmp_path_factory.mktemp("bad-layout")
    (run / "run.mcap").symlink_to(shipped_runs["triangle"] / "run.mcap")
    layout = {
        "configById": {
            "Plot!bad": {
                "paths": [
                    {
                        "value": "/execute/sample.position.no_such_joint",
                        "enabled": True,
                        "timestampMethod": "receiveTime",
                    }
                ]
            },
            "3D!bad": {
                "followTf": "no_such_frame",
                "topics": {},
                "layers": {
                    "robot": {"layerId": "foxglove.Urdf", "url": "data:application/xml,<robot name='cut'><link"}
                },
            },
        },
        "layout": "Plot!bad",
    }
    (run / LAYOUT_FILE).write_text(json.dumps(layout))
    return run


@pytest.fixture(scope="module")
def parsed(runs, bad_run) -> dict[str, list[dict]]:
    """Run name (and "bad layout": :func:`bad_run`) -> the Node check's lines for its run: its channels, then its
    layout's panels."""
    runs = {**runs, "bad layout": bad_run}
    lines = _node(
        "check-mcap.cjs",
        *[arg for run in runs.values() for arg in (*_layout_args(run), str(run / "run.mcap"))],
        timeout_s=600,
    )
    return {name: [line for line in lines if line["mcap"] == str(run / "run.mcap")] for name, run in runs.items()}


@pytest.mark.parametrize("task", RUNS)
def test_every_channel_parses_and_decodes_in_studio(parsed, task):
    channels = [line for line in parsed[task] if "panel" not in line]
    failing = {
        line["topic"]: line.get("parse_error")
        or line["problems"]
        or line.get("urdf")
        or f"{line['decoded']} of {line['messages']} decoded"
        for line in channels
        if not line["ok"]
    }
    assert failing == {}
    assert channels and all(line["decoded"] == line["messages"] > 0 for line in channels)


@pytest.mark.parametrize("task", RUNS)
def test_robot_description_parses_with_studios_urdf_parser_and_every_mesh_loads(parsed, runs, task):
    """Studio's URDF parser reads every link of the robot's URDF, and every mesh it draws is one Studio's 3D panel
    fetches and loads (counted here with ElementTree: the Panda's 11 visual meshes)."""
    (urdf,) = [line["urdf"] for line in parsed[task] if line.get("topic") == "/robot_description"]
    assert urdf["ok"], urdf.get("error")
    robot = ET.parse(load_robot(json.loads((runs[task] / "manifest.json").read_text())["robot_dir"]).urdf.path)
    assert urdf["links"] == len(robot.getroot().findall("link"))
    assert urdf["meshes"] == len(robot.getroot().findall("link/visual/geometry/mesh"))


@pytest.mark.parametrize("task", RUNS)
def test_studio_can_plot_every_path_of_the_runs_layout(parsed, runs, task):
    """Each plot path is a plottable field by Studio's message path code and holds values; the 3D panel's frame is on
    /tf and joins its scene topics' frames."""
    assert (runs[task] / LAYOUT_FILE).is_file(), f"the run has no {LAYOUT_FILE}"
    panels = [line for line in parsed[task] if "panel" in line]
    assert {line["panel"] for line in panels} == set(json.loads((runs[task] / LAYOUT_FILE).read_text())["configById"])
    assert [line for line in panels if not line["ok"]] == []


def test_the_node_check_reports_what_studio_cannot_show(parsed):
    """The negative control: a path to a field the schema has not, a frame /tf has not, and a URDF layer whose URDF is
    cut short."""
    by_kind = {line["kind"]: line for line in parsed["bad layout"] if "panel" in line}
    assert not by_kind["Plot"]["ok"] and by_kind["Plot"]["paths"][0]["error"] is not None
    assert not by_kind["3D"]["ok"] and not by_kind["3D"]["follow_on_tf"]
    assert not by_kind["3D"]["urdf_layers"]["robot"]["ok"]


@pytest.mark.parametrize("task", RUNS)
def test_the_layouts_urdf_layer_parses_with_studios_urdf_parser(parsed, task):
    """The layout's 3D panel draws the robot from a URDF layer (drawn when the panel mounts), fetched from its url."""
    (three_d,) = [line for line in parsed[task] if line.get("kind") == "3D"]
    assert three_d["urdf_layers"]["robot"]["ok"] and three_d["urdf_layers"]["robot"]["links"] > 1


def test_quoted_field_names_parse_in_studio():
    """Joint names outside Studio's plain field grammar are quoted so that its parser gives them back whole."""
    names = ["left_elbow", "joint 1", 'a"b.c']
    script = (
        f"const {{ loadMessagePathSupport }} = require({json.dumps(str(FOXGLOVE / 'lib' / 'studioBundle.cjs'))});"
        f"const {{ parseRosPath }} = loadMessagePathSupport();"
        f"for (const p of {json.dumps([message_path('/execute/sample', 'position', n) for n in names])})"
        " console.log(JSON.stringify(parseRosPath(p)));"
    )
    done = subprocess.run(
        [str(NODE), "-e", script], capture_output=True, text=True, timeout=120, check=True, cwd=FOXGLOVE
    )
    parsed_paths = [json.loads(line) for line in done.stdout.splitlines()]
    assert [(p["topicName"], [part["name"] for part in p["messagePath"]]) for p in parsed_paths] == [
        ("/execute/sample", ["position", n]) for n in names
    ]


# -- the whole Studio app, in headless Chromium ------------------------------------------------------


@pytest.fixture(scope="module")
def opened(runs, tmp_path_factory) -> dict[str, dict]:
    """Run name -> what Studio showed for its run opened with the run's layout, for the runs of :data:`OPENED` (one
    browser, the runs one after the other)."""
    missing = [task for task in OPENED if not (runs[task] / LAYOUT_FILE).is_file()]
    assert not missing, f"runs without {LAYOUT_FILE}: {missing}"
    out = tmp_path_factory.mktemp("studio")
    args = [arg for task in OPENED for arg in ("--layout", str(runs[task] / LAYOUT_FILE), str(runs[task] / "run.mcap"))]
    results = _node("open-in-studio.cjs", "--out", str(out), *args, timeout_s=300 * len(OPENED))
    return {task: result for task, result in zip(OPENED, results, strict=True)}


@pytest.fixture(scope="module")
def imported(runs, tmp_path_factory) -> dict[str, dict]:
    """Run name -> what Studio showed for the runs of :data:`IMPORTED`, each opened with Studio's default layout, then
    its own imported twice from the Layouts sidebar (the second import mounts the panels again with the same topics)."""
    out = tmp_path_factory.mktemp("studio-import")
    args = [
        arg for task in IMPORTED for arg in ("--layout", str(runs[task] / LAYOUT_FILE), str(runs[task] / "run.mcap"))
    ]
    results = _node("open-in-studio.cjs", "--import", "2", "--out", str(out), *args, timeout_s=300 * len(IMPORTED))
    return {task: result for task, result in zip(IMPORTED, results, strict=True)}


@needs_chromium
@pytest.mark.parametrize("task", OPENED)
def test_studio_draws_the_robot_on_opening_without_a_click(opened, task):
    """Before anything is clicked, the robot covers at least half the pixels it covers mid-run (its links' frame axes
    alone: 15 %)."""
    assert opened[task]["robot_pixels_on_open"] >= 0.5 * opened[task]["robot_pixels"] > 0


@needs_chromium
@pytest.mark.parametrize("task", IMPORTED)
def test_studio_draws_the_robot_when_the_layout_is_imported_after_the_file_without_a_click(imported, task):
    assert imported[task]["robot_pixels_on_open"] >= 0.5 * imported[task]["robot_pixels"] > 0
    assert imported[task]["urdf_parsed"] and imported[task]["layer_errors"] == []


@needs_chromium
@pytest.mark.parametrize("task", OPENED)
def test_studio_reports_no_problem(opened, task):
    assert opened[task]["problems"] == [] and opened[task]["problems_tab"] == "No problems found"


@needs_chromium
@pytest.mark.parametrize("task", OPENED)
def test_studios_3d_panel_reports_no_layer_error(opened, task):
    """No "Missing transform" (the reference path's base_link joined to world), nor any other layer error."""
    assert opened[task]["urdf_parsed"], opened[task]["urdf_error"]
    assert opened[task]["layer_errors"] == []


def _robot_mask(with_urdf: Path, without: Path) -> np.ndarray:
    """Pixels of the first screenshot that no pixel within one pixel of the second matches: where the URDF layer drew.

    The two 3D panels may differ by a pixel in size (their split), so they project the same scene up to
    a pixel apart; their outermost :data:`BORDER_PX` rows and columns are left out.
    """
    a = np.asarray(Image.open(with_urdf).convert("RGB"), dtype=np.int16)
    b = np.asarray(Image.open(without).convert("RGB"), dtype=np.int16)
    h, w = min(a.shape[0], b.shape[0]) - 2 * BORDER_PX, min(a.shape[1], b.shape[1]) - 2 * BORDER_PX
    a = a[BORDER_PX : BORDER_PX + h, BORDER_PX : BORDER_PX + w]
    b = b[BORDER_PX - 1 : BORDER_PX + h + 1, BORDER_PX - 1 : BORDER_PX + w + 1]
    matched = np.zeros((h, w), bool)
    for dy in range(3):
        for dx in range(3):
            matched |= (np.abs(a - b[dy : dy + h, dx : dx + w]) <= TOLERANCE).all(axis=2)
    return ~matched


@needs_chromium
@pytest.mark.parametrize("task", OPENED)
def test_studio_draws_the_whole_robot(opened, task):
    """The 3D panel with the URDF layer differs from its twin without it over a robot-sized area, clear of the panel's
    edges."""
    shots = Path(opened[task]["screenshots"])
    mask = _robot_mask(shots / "3d-urdf.png", shots / "3d-bare.png")
    rows, cols = np.nonzero(mask)
    assert mask.mean() > 0.01, f"{mask.sum()} robot pixels of {mask.size}"
    height, width = mask.shape
    assert (
        rows.min() >= MARGIN_PX
        and cols.min() >= MARGIN_PX
        and rows.max() < height - MARGIN_PX
        and cols.max() < width - MARGIN_PX
    )
    assert rows.max() - rows.min() > 0.3 * height  # a 1.6 m robot, not a speck


def test_every_plot_of_the_layout_spans_its_units_floor_and_its_stages_clock(runs):
    """Each Plot panel's y-range (the ``minYValue`` and ``maxYValue`` Studio's Plot panel reads) is at least its unit's
    floor wide and holds every value of its paths, read from run.mcap with the mcap reader: the triangle's arm angle,
    which MC-Inverse holds to 1e-12 rad, sits in a plot at least 1e-3 rad wide. Its x-range (``minXValue``,
    ``maxXValue``, not synced with the other plots) is its topic's first and last ``t``: on carry_box the IK's 20 s and
    the execution's 6.3 s apart. Its series have colours of their own."""
    from mcap.reader import make_reader

    from dualarm.record.sink import PLOT_FLOORS

    units = {"[m]": "m", "[rad]": "rad", "contacts": "count"}
    for task, run in runs.items():
        layout = json.loads((run / LAYOUT_FILE).read_text())
        values: dict[str, list[float]] = {}
        with (run / "run.mcap").open("rb") as f:
            for _, channel, message in make_reader(f).iter_messages():
                if channel.topic.endswith("/sample") or channel.topic.endswith("/executed"):
                    data = json.loads(message.data)
                    for field, value in data.items():
                        for key, v in value.items() if isinstance(value, dict) else [(None, value)]:
                            if isinstance(v, (int, float)):
                                fields = (field,) if key is None else (field, key)
                                values.setdefault(message_path(channel.topic, *fields), []).append(float(v))
        for panel, config in layout["configById"].items():
            if not panel.startswith("Plot!"):
                continue
            title = config["foxglovePanelTitle"]
            unit = next(unit for word, unit in units.items() if word in title)
            low, high = config["minYValue"], config["maxYValue"]
            shown = np.concatenate([values[p["value"]] for p in config["paths"]])
            assert high - low >= PLOT_FLOORS[unit] * (1 - 1e-9), (task, title)
            assert low <= shown.min() and shown.max() <= high, (task, title)
            if task == "triangle" and panel == "Plot!arm-angle":  # each hand's held angle
                assert max(np.ptp(values[p["value"]]) for p in config["paths"]) < 1e-12
            (topic,) = {p["value"].split(".")[0] for p in config["paths"]}
            clock = values[message_path(topic, "t")]
            assert (config["minXValue"], config["maxXValue"]) == (min(clock), max(clock)), (task, title)
            assert config["isSynced"] is False and len({p["color"] for p in config["paths"]}) == len(config["paths"])
        if task == "carry_box":
            ik, executed = (layout["configById"][p]["maxXValue"] for p in ("Plot!arm-angle", "Plot!hand-error"))
            assert ik > 2 * executed, (ik, executed)


def test_the_carried_box_is_a_scene_entity_of_the_3d_panel(parsed, runs):
    """carry_box: the box its hands carry is on /execute/object, every message decoded by Studio, one per animation
    step of the execution, and shown by the layout's 3D panel."""
    (box,) = [line for line in parsed["carry_box"] if line.get("topic") == "/execute/object"]
    assert box["ok"] and box["decoded"] == box["messages"] > 100, box
    layout = json.loads((runs["carry_box"] / LAYOUT_FILE).read_text())
    assert layout["configById"]["3D!dualarm"]["topics"]["/execute/object"]["visible"]


@needs_chromium
def test_studio_draws_the_exported_ros2_bag_robot_moving(runs, tmp_path):
    """``dualarm export --ros2``'s bag (ros2msg, CDR) opened in Studio with a layout of one 3D panel on /tf's world:
    no problem, the robot drawn from /robot_description and /tf on opening and mid-run, and moved between the two."""
    from tests.helpers import dualarm_subprocess

    done = dualarm_subprocess(["export", str(runs["carry_box"]), "--ros2", str(tmp_path / "bag")])
    assert done.returncode == 0, done.stderr
    (mcap_file,) = (tmp_path / "bag").glob("*.mcap")
    layout = json.loads((runs["carry_box"] / LAYOUT_FILE).read_text())  # its playback settings and the 3D panel's
    three_d = {**layout["configById"]["3D!dualarm"], "topics": {"/robot_description": {"visible": True}}, "layers": {}}
    layout = {**layout, "configById": {"3D!bag": three_d}, "layout": "3D!bag"}
    (tmp_path / "layout.json").write_text(json.dumps(layout))
    (shown,) = _node(
        "open-in-studio.cjs",
        "--out",
        str(tmp_path / "shots"),
        "--layout",
        str(tmp_path / "layout.json"),
        str(mcap_file),
        timeout_s=300,
    )
    assert shown["ok"] and shown["problems"] == [] and shown["urdf_parsed"], shown
    shots = Path(shown["screenshots"])
    opened, middle = (_robot_mask(shots / name, shots / "3d-bare.png") for name in ("3d-open.png", "3d-urdf.png"))
    assert opened.mean() > 0.01 and middle.mean() > 0.01
    assert (opened != middle).sum() > 0.05 * middle.sum()  # the arms moved between the start and the middle
