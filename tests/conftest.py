"""Shared fixtures: the repository's robot and task directories."""

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
HUMANOID = REPO / "robots" / "humanoid"
TASKS = REPO / "tasks"


@pytest.fixture(scope="session")
def humanoid():
    from pipeline.model.robot import load_robot

    return load_robot(HUMANOID)


@pytest.fixture(scope="session")
def kuka_urdf() -> Path:
    """The KUKA LBR iiwa shipped in pybullet_data: a second, independent S-R-S arm."""
    import pybullet_data

    return Path(pybullet_data.getDataPath()) / "kuka_iiwa" / "model.urdf"
