"""PD²GS part discovery (paper Sec. 3.3-3.5, App. A): motion-based coarse parts, part counting,
visibility-prompted masks and boundary-aware Gaussian splitting, joint estimation, TSDF part meshes,
and the rsart-submission/1 writer. Entry points: :func:`pd2gs.discovery.pipeline.discover` and
:func:`pd2gs.discovery.submission.write_submission`; settings: :class:`DiscoveryConfig`.
"""
from .config import DiscoveryConfig, VLMConfig
from .field import StateField, as_state_field

__all__ = ["DiscoveryConfig", "VLMConfig", "StateField", "as_state_field"]
