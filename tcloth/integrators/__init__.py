"""Integrators by name."""
from .explicit import RK4, ForwardEuler, SymplecticEuler, Verlet
from .implicit import BackwardEuler
from .projective import Projective

INTEGRATORS = {cls.name: cls for cls in (ForwardEuler, SymplecticEuler, Verlet, RK4,
                                         BackwardEuler, Projective)}

__all__ = ["INTEGRATORS"]
