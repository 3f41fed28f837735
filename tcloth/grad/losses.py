"""Losses for ``Trajectory.gradient``: scalar functions of the states at chosen steps,
each with its gradient.

A loss gives ``steps`` (the steps it reads: 0 is the initial state, ``steps`` the last)
and ``evaluate(step, x, v) -> (value, dL/dx, dL/dv or None)`` with x, v (n, 3) NumPy.
``Loss(steps, function)`` wraps a user's function of that form; ``Sum`` adds losses.
"""
import numpy as np

from ..errors import SceneError
from ..validate import as_int


class Loss:
    """A user's loss: ``function(step, x, v) -> (value, dL/dx, dL/dv or None)`` read at
    ``steps`` (an int or an iterable of them)."""

    def __init__(self, steps, function=None):
        steps = [steps] if np.isscalar(steps) else list(steps)
        if not steps:
            raise SceneError("steps must name at least one step (got none)")
        self.steps = tuple(as_int(f"steps[{i}]", s, 0) for i, s in enumerate(steps))
        self.function = function

    def evaluate(self, step, x, v):
        return self.function(step, x, v)

    def __add__(self, other):
        return Sum(self, other)


class Sum(Loss):
    """The sum of losses."""

    def __init__(self, *losses):
        super().__init__(sorted({s for loss in losses for s in loss.steps}))
        self.losses = losses

    def evaluate(self, step, x, v):
        value, dx, dv = 0.0, np.zeros_like(x), np.zeros_like(v)
        for loss in self.losses:
            if step in loss.steps:
                lv, lx, lvv = loss.evaluate(step, x, v)
                value, dx = value + lv, dx + lx
                if lvv is not None:
                    dv = dv + lvv
        return value, dx, dv


class TargetPositions(Loss):
    """sum over the chosen particles of weight/2 |x_i - target_i|^2 at ``steps``.

    targets: (k, 3) positions, m; particles: (k,) particle ids (default all, k = n);
    weight: a scalar."""

    def __init__(self, targets, steps, particles=None, weight=1.0):
        super().__init__(steps)
        self.targets = np.asarray(targets, dtype=np.float64)
        if self.targets.ndim != 2 or self.targets.shape[1] != 3:
            raise SceneError(f"targets must have shape (k, 3) (got {self.targets.shape})")
        self.particles = (np.arange(len(self.targets)) if particles is None
                          else np.asarray(particles, dtype=np.int64))
        if self.particles.shape != (len(self.targets),):
            raise SceneError(f"particles must have shape ({len(self.targets)},) (got "
                             f"{self.particles.shape})")
        self.weight = float(weight)

    def evaluate(self, step, x, v):
        diff = x[self.particles] - self.targets
        dx = np.zeros_like(x)
        np.add.at(dx, self.particles, self.weight * diff)
        return 0.5 * self.weight * float((diff * diff).sum()), dx, None


class TargetCloud(Loss):
    """The one-sided Chamfer distance to a point cloud: mean over particles of the squared
    distance to the nearest target point, at ``steps`` (targets (k, 3), m). Its gradient
    holds each particle's nearest point fixed (the function is smooth wherever nearest
    points are unique)."""

    def __init__(self, targets, steps):
        super().__init__(steps)
        self.targets = np.asarray(targets, dtype=np.float64)
        if self.targets.ndim != 2 or self.targets.shape[1] != 3 or not len(self.targets):
            raise SceneError(f"targets must have shape (k, 3), k >= 1 (got "
                             f"{self.targets.shape})")

    def evaluate(self, step, x, v):
        d2 = ((x[:, None, :] - self.targets[None, :, :]) ** 2).sum(axis=2)
        nearest = d2.argmin(axis=1)
        diff = x - self.targets[nearest]
        n = len(x)
        return float((diff * diff).sum()) / n, 2.0 * diff / n, None
