"""The material catalogue of retrofit variants: :mod:`wallcal.materials` (kept importable here)."""

from ..materials import PROPERTY_KEYS, Material, catalogue, find, unknown_message

__all__ = ["PROPERTY_KEYS", "Material", "catalogue", "find", "unknown_message"]
