"""PD²GS articulated Gaussian model (issue 21): canonical Gaussians owned by rigid bodies on a kinematic
tree, posed per state (:mod:`.model`), fitted end to end (:mod:`.fit`, with :mod:`.ownership`'s discrete
re-assignment), initialised from stage 1 (:mod:`pd2gs.discovery.initialise`), pruned / merged / re-parented by held-out loss
(:mod:`.select`); synthetic test scenes in :mod:`.scenes`, measurements in :mod:`.experiment`.

See docs/pd2gs-articulated.md.
"""
from .model import ArticulatedGaussians, BodyPoses, ModelError, canonical_gaussians

__all__ = ["ArticulatedGaussians", "BodyPoses", "ModelError", "canonical_gaussians"]
