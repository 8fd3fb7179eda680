"""The path stage: a task's hand motions as a sampled Cartesian reference."""

from pipeline.paths.build import build_reference
from pipeline.paths.reference import CartesianReference, HandReference

__all__ = ["CartesianReference", "HandReference", "build_reference"]
