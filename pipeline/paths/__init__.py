"""The path stage: a task's hand motions as a sampled Cartesian reference."""

from dualarm.paths.build import build_reference
from dualarm.paths.reference import CartesianReference, HandReference

__all__ = ["CartesianReference", "HandReference", "build_reference"]
