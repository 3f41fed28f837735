"""Integrators by name."""
from .explicit import RK4, ForwardEuler, SymplecticEuler, Verlet
from .implicit import BackwardEuler
from .projective import Projective
from .vbd import VBD

INTEGRATORS = {cls.name: cls for cls in (ForwardEuler, SymplecticEuler, Verlet, RK4,
                                         BackwardEuler, Projective, VBD)}

__all__ = ["INTEGRATORS"]
