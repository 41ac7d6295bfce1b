"""PD²GS: a canonical 3D Gaussian field warped into interaction states by a latent-conditioned MLP.

Modules: ``render`` (rasterizer backends), ``gaussians`` (canonical field), ``deform``
(deformation network + latents), ``densify`` (adaptive density control), ``train`` (trainer),
``data`` (frames from ``rsart.load``), ``synthetic`` (test scene), ``cli`` (``pd2gs`` command).

Importing pd2gs before torch sets OMP_WAIT_POLICY=PASSIVE (unless already set): on a small,
shared CPU box spinning OpenMP workers made training steps up to 6x slower (measured).

It also puts numba's OpenMP threading layer first (``NUMBA_THREADING_LAYER_PRIORITY="omp workqueue tbb"``,
unless set): numba's default order tries TBB first, and an installed TBB older than 2021.6 then prints a
NumbaWarning at the first parallel kernel. OpenMP is what torch uses too; workqueue (always available) is the
fallback, so TBB is never reached.
"""
import os as _os
import sys as _sys

_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
_os.environ.setdefault("NUMBA_THREADING_LAYER_PRIORITY", "omp workqueue tbb")
if "numba" in _sys.modules:  # numba read its config already: set it there too (before any parallel launch)
    _cfg = _sys.modules["numba"].config
    if _cfg.THREADING_LAYER_PRIORITY == ["tbb", "omp", "workqueue"]:  # numba's default, not a user's choice
        _cfg.THREADING_LAYER_PRIORITY = _os.environ["NUMBA_THREADING_LAYER_PRIORITY"].split()

__version__ = "0.1.0"
