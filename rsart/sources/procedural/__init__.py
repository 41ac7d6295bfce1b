"""Procedural articulated digital twins and the built-in ``rsart-synth`` benchmark.

``generate(category, seed)`` builds a seeded twin (:class:`rsart.kinematics.Twin` with textured
visuals); ``write_generated`` writes it as an object folder through ``rsart.twin_io.write_object``;
``write_suite`` writes the whole ``rsart-synth`` dataset. See docs/procedural.md.
"""
from __future__ import annotations

import importlib

__all__ = ["CATEGORIES", "GENERATOR", "PARTNET_LIKE", "RS_ART_LIKE", "VERSION", "Generated", "generate", "object_id"]


def __getattr__(name: str):
    """The registry's names, imported on first use (the catalogue alone must not pull in trimesh)."""
    if name in __all__:
        value = getattr(importlib.import_module(".registry", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
