"""The path stage: a task's hand motions as a sampled Cartesian reference."""

from dualarm.contracts.reference import CartesianReference, HandReference
from dualarm.paths.build import build_reference

__all__ = ["CartesianReference", "HandReference", "build_reference"]
