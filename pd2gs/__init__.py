"""PD²GS: a canonical 3D Gaussian field warped into interaction states by a latent-conditioned MLP.

Subpackages/modules: ``render`` (rasterizer backends), ``gaussians`` (canonical field),
``deform`` (deformation network + latents), ``train`` (trainer), ``cli`` (``pd2gs`` command).
"""

__version__ = "0.1.0"
