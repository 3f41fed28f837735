"""Integrators by name."""
from .explicit import RK4, ForwardEuler, SymplecticEuler, Verlet
from .implicit import BackwardEuler

INTEGRATORS = {cls.name: cls for cls in (ForwardEuler, SymplecticEuler, Verlet, RK4,
                                         BackwardEuler)}

__all__ = ["INTEGRATORS"]
