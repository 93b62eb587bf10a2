"""CARL's ``carl.envs.rna``: RNA design (with the ``rna`` extra installed)."""

from contextrl.carl.envs.registry import carl_classes, carl_names, family_getattr

globals().update(carl_classes("rna"))
__getattr__ = family_getattr("rna")
__all__ = carl_names("rna")
