"""Integrators by name."""
from .explicit import RK4, ForwardEuler, SymplecticEuler, Verlet

INTEGRATORS = {cls.name: cls for cls in (ForwardEuler, SymplecticEuler, Verlet, RK4)}

__all__ = ["INTEGRATORS"]
