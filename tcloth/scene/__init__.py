"""The scene: what a user describes, in NumPy, every input checked when it is given.

``scene.py`` (``Scene``: particles, springs, cloths, ropes, colliders), ``builders.py``
(Provot grid cloth, mesh cloth, rope), ``fabric.py`` (``Fabric``: measured material to
springs, membrane and hinges), ``hinges.py`` (a cloth's bending hinges), ``objfile.py``
(OBJ in), ``stability.py`` (the explicit stability limit of a scene's springs, from the
scene alone). The optional features' Scene methods come from ``tcloth.features``.
"""
from .scene import Scene

__all__ = ["Scene"]
