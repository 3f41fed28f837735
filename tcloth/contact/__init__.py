"""Contact: the self-contact topology and exclusion rule (``topology.py``), closest points
and the separating planes' normals (``normals.py``), the proximity list's broad phase
(``broad.py``) and the swept-box search of a step (``swept.py``), both one candidate search
(``search.py``) over the cell hash's grids (``hashgrid.py``), the mesh colliders' pairs
(``obstacle.py``, ``obstacle_search.py``, ``field_sweep.py``), the guard that keeps every
step's motion from crossing cloth or entering colliders (``guard.py``, ``projection.py``),
and the stage that owns them, one per simulator (``stage.py``; docs/contact.md).

A solver reaches contact through what this package exports: the simulator's
``ContactStage`` (handed to its integrator; ``solve.py`` is the part a solver calls inside
its step) and projective dynamics' ``PlaneConstraints`` (``planes.py``).
"""
from .planes import PlaneConstraints
from .stage import ContactStage

__all__ = ["ContactStage", "PlaneConstraints"]
