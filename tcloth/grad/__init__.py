"""Reverse-mode gradients through the simulation (docs/grad.md).

``Trajectory(scene, steps, dt, integrator)`` runs a scene and differentiates a loss
(``losses``) over its states with respect to material, scene, initial-state and control
parameters: the symplectic Euler step's exact adjoint and the converged backward Euler
step's (the implicit function theorem, the adjoint solved by the integrator's own CG).
"""
from .losses import (ChordAngle, DrapeCoefficient, Loss, Measured, Sum, TargetCloud,
                     TargetPositions)
from .trajectory import INTEGRATORS, Result, Trajectory

__all__ = ["Trajectory", "Result", "INTEGRATORS", "Loss", "Sum", "TargetPositions",
           "TargetCloud", "Measured", "ChordAngle", "DrapeCoefficient"]
