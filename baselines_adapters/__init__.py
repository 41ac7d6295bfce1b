"""baselines_adapters: run the published baselines (PARIS, ArticulatedGS, DTArt, ArtGS, REArtGS) on
any rsart data and score them with rsart-eval (docs/baselines.md).

Per method an exporter writes an rsart object in the method's own input layout (with the paper's
capture protocol for that family) and an importer turns the method's outputs into an entry of an
``rsart-submission/1`` file. Adapters are found by :func:`available` — the built-ins below plus any
registered in the entry-point group ``rsart.adapters`` — and by the ``rsart adapters | export |
import`` commands (rsart/cli/adapters.py), which use the entry points only.
"""
__version__ = "0.1.0"

from .registry import BUILTIN, available, get_adapter  # noqa: E402

__all__ = ["BUILTIN", "available", "get_adapter", "__version__"]
