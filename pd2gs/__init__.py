"""PD²GS: a canonical 3D Gaussian field warped into interaction states by a latent-conditioned MLP.

Modules: ``render`` (rasterizer backends), ``gaussians`` (canonical field), ``deform``
(deformation network + latents), ``densify`` (adaptive density control), ``train`` (trainer),
``data`` (frames from ``rsart.load``), ``synthetic`` (test scene), ``cli`` (``pd2gs`` command).

Importing pd2gs before torch sets OMP_WAIT_POLICY=PASSIVE (unless already set): on a small,
shared CPU box spinning OpenMP workers made training steps up to 6x slower (measured).
"""
import os as _os

_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

__version__ = "0.1.0"
