"""Procedural articulated digital twins and the built-in ``rsart-synth`` benchmark.

``generate(category, seed)`` builds a seeded twin (:class:`rsart.kinematics.Twin` with textured
visuals); ``write_generated`` writes it as an object folder through ``rsart.twin_io.write_object``;
``write_suite`` writes the whole ``rsart-synth`` dataset. See docs/procedural.md.
"""
from .registry import CATEGORIES, GENERATOR, PARTNET_LIKE, RS_ART_LIKE, VERSION, Generated, generate, object_id

__all__ = ["CATEGORIES", "GENERATOR", "PARTNET_LIKE", "RS_ART_LIKE", "VERSION", "Generated", "generate", "object_id"]
