"""The model: a scene as static Taichi fields, built once (``model.py``: ``Model`` and the
per-step ``State``), with the cloth grids' layout (``grid.py``) and the colliders' table
(``collider_table.py``). Features' objects come from ``tcloth.features``; the contact
stage from ``tcloth.contact``."""
from .model import Model, State

__all__ = ["Model", "State"]
