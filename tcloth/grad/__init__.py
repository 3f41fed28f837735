"""Reverse-mode gradients through the simulation (docs/grad.md).

``Trajectory(scene, steps, dt, integrator)`` runs a scene and differentiates a loss
(``losses``) over its states with respect to material, scene, initial-state and control
parameters: the symplectic Euler step's exact adjoint and the converged backward Euler
and projective dynamics steps' (the implicit function theorem, the adjoint solved by the
integrator's own CG, or by flexible GMRES).
"""
from .losses import (ChordAngle, DrapeCoefficient, KernelLoss, Loss, Measured, Sum,
                     TargetCloud, TargetPositions)
from .result import Result
from .trajectory import INTEGRATORS, Trajectory

__all__ = ["Trajectory", "Result", "INTEGRATORS", "Loss", "KernelLoss", "Sum",
           "TargetPositions", "TargetCloud", "Measured", "ChordAngle", "DrapeCoefficient"]
