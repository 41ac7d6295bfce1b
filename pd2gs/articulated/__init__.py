"""PD²GS articulated Gaussian model (issue 21): canonical Gaussians owned by rigid bodies on a kinematic
tree, posed per state, fitted end to end (:mod:`.fit`), initialised from stage 1 (:mod:`.init`).

See docs/pd2gs-articulated.md.
"""
from .model import ArticulatedGaussians, BodyPoses, ModelError, canonical_gaussians

__all__ = ["ArticulatedGaussians", "BodyPoses", "ModelError", "canonical_gaussians"]
