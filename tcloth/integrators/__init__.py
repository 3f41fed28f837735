"""Integrators by name."""
from .explicit import RK4, ForwardEuler, SymplecticEuler, Verlet
from .implicit import BackwardEuler
from .projective import Projective
from .vbd import VBD
from .xpbd import XPBD

INTEGRATORS = {cls.name: cls for cls in (ForwardEuler, SymplecticEuler, Verlet, RK4,
                                         BackwardEuler, Projective, VBD, XPBD)}

__all__ = ["INTEGRATORS"]
