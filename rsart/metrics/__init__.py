"""The articulated-reconstruction metrics of the literature (PARIS -> DTArt -> ArtGS), usable without the CLI.

* :mod:`rsart.metrics.chamfer` — Chamfer distance (CD-s, CD-m, CD-w) with the 10%-component filter.
* :mod:`rsart.metrics.joints` — Axis Ang, Axis Pos, Part Motion.
* :mod:`rsart.metrics.matching` — Hungarian matching of predicted to true movable parts.
* :mod:`rsart.metrics.images` — PSNR, SSIM, part-mask IoU / accuracy / F1.

Formulas, units and where this toolkit differs from the peers: docs/evaluation.md.
"""
from .chamfer import (ChamferConfig, chamfer_distance, chamfer_floor, chamfer_mesh, filter_small_components,
                      sample_surface, stable_seed)
from .images import mask_scores, psnr, ssim
from .joints import (JointEstimate, axis_angle_deg, axis_position, joint_errors, line_distance, part_motion,
                     rotation_geodesic_deg)
from .matching import Match, match_parts

__all__ = [
    "ChamferConfig", "chamfer_distance", "chamfer_floor", "chamfer_mesh", "filter_small_components",
    "sample_surface", "stable_seed", "psnr", "ssim", "mask_scores", "JointEstimate", "axis_angle_deg",
    "axis_position", "joint_errors", "line_distance", "part_motion", "rotation_geodesic_deg", "Match", "match_parts",
]
