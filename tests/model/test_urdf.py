"""The URDF as viewers read it (:func:`dualarm.model.urdf.viewer_urdf`), checked with PyBullet."""

import xml.etree.ElementTree as ET

import numpy as np
import pybullet as pb
import pytest

from dualarm.model.urdf import viewer_urdf
from dualarm.sim.world import load_pybullet_robot
from tests.helpers import HUMANOID

pytestmark = pytest.mark.integration

URDF = HUMANOID / "humanoid.urdf"


def _collision_boxes(path) -> dict[str, np.ndarray]:
    """Link name -> PyBullet's axis-aligned bounding box of its collision shapes at the zero pose (2, 3) [m]."""
    with load_pybullet_robot(path) as sim:
        return {
            name: np.array(pb.getAABB(sim.body, index, physicsClientId=sim.client))
            for name, index in sim.link_index.items()
        }


def test_capsules_become_urdf_1_0_shapes_that_pybullet_bounds_alike(tmp_path):
    """Each capsule becomes a cylinder and two spheres: PyBullet, which reads both, bounds every link's collision shapes
    in the same box."""
    text = URDF.read_text()
    published = tmp_path / "humanoid.urdf"
    published.write_text(viewer_urdf(text))
    shapes = {
        e.tag for e in ET.parse(published).getroot().iter() if e.tag in ("box", "cylinder", "sphere", "mesh", "capsule")
    }
    assert "capsule" in text and shapes <= {"box", "cylinder", "sphere", "mesh"}
    original, viewed = _collision_boxes(URDF), _collision_boxes(published)
    assert original.keys() == viewed.keys()
    for link, box in original.items():
        np.testing.assert_allclose(
            viewed[link], box, atol=4e-3, err_msg=link
        )  # Bullet pads a cylinder's box by its collision margin (3 mm here), a capsule's not
