"""Losses for ``Trajectory.gradient``: scalar functions of the states at chosen steps,
each with its gradient.

A loss gives ``steps`` (the steps it reads: 0 is the initial state, ``steps`` the last)
and ``evaluate(step, x, v) -> (value, dL/dx, dL/dv or None)`` with x, v (n, 3) NumPy.
``Loss(steps, function)`` wraps a user's function of that form, ``KernelLoss`` a Taichi
kernel that Taichi's reverse mode differentiates; ``Sum`` adds losses.
``Measured`` losses compare a measurement of the positions with a target, ((m(x) -
target) / scale)^2: the textile tests' ``ChordAngle`` (Peirce's cantilever) and
``DrapeCoefficient`` (Cusick's drape); each gives ``measure(x) -> (m, dm/dx)`` too.
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..errors import SceneError
from ..validate import as_int, as_scalar


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


class KernelLoss(Loss):
    """A loss written as a Taichi kernel: ``kernel(x, v, loss)`` adds its value at one of
    ``steps`` to ``loss[None]`` (a scalar field) from the positions x and velocities v
    (Vector fields of the scene's n particles) within Taichi's rules for reverse mode
    (accumulate with ``+=``, write nothing to x or v); its gradient is the kernel's
    ``grad`` (Taichi's reverse mode), so none is written by hand. The fields are made in
    the runtime's precision at the first evaluation."""

    def __init__(self, kernel, steps, n):
        super().__init__(steps)
        if not callable(getattr(kernel, "grad", None)):
            raise SceneError(f"kernel must be a Taichi kernel, whose reverse mode gives the "
                             f"gradient (got {kernel!r})")
        self.kernel, self.n, self.fields = kernel, as_int("n", n, 1), None

    def evaluate(self, step, x, v):
        if x.shape != (self.n, 3) or v.shape != (self.n, 3):
            raise SceneError(f"KernelLoss was made for n = {self.n} particles (got x of "
                             f"shape {x.shape}, v of shape {v.shape})")
        if self.fields is None:
            real = runtime.real()
            self.fields = (ti.Vector.field(3, real, shape=self.n, needs_grad=True),
                           ti.Vector.field(3, real, shape=self.n, needs_grad=True),
                           ti.field(real, shape=(), needs_grad=True))
        xf, vf, loss = self.fields
        npr = runtime.numpy_real()
        xf.from_numpy(x.astype(npr))
        vf.from_numpy(v.astype(npr))
        loss[None] = 0.0
        self.kernel(xf, vf, loss)
        xf.grad.fill(0.0)
        vf.grad.fill(0.0)
        loss.grad[None] = 1.0
        self.kernel.grad(xf, vf, loss)
        return (float(loss[None]), xf.grad.to_numpy().astype(np.float64),
                vf.grad.to_numpy().astype(np.float64))


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


def _ids(name, ids, least):
    """Particle ids as a 1-D int array of at least ``least``."""
    out = np.atleast_1d(np.asarray(ids))
    if out.ndim != 1 or len(out) < least or not np.issubdtype(out.dtype, np.integer):
        raise SceneError(f"{name} must be at least {least} particle ids (got {ids!r})")
    return out.astype(np.int64)


class Measured(Loss):
    """((m(x) - target) / scale)^2 at ``steps`` for a measurement m of the positions, its
    ``measure(x) -> (value, dm/dx)`` given by a subclass; losses add, so a fit to several
    measurements is their sum, each in its own unit ``scale``."""

    def __init__(self, steps, target, scale):
        super().__init__(steps)
        self.target = as_scalar("target", target)
        self.scale = as_scalar("scale", scale, minimum=0.0, strict=True)

    def evaluate(self, step, x, v):
        value, g = self.measure(x)
        r = (value - self.target) / self.scale
        return r * r, 2.0 * r / self.scale * g, None


class ChordAngle(Measured):
    """Peirce's cantilever: the chord's angle below the horizontal, degrees, from particle
    ``clamp`` (on the clamp line) to the mean of the ``tip`` particles (the tip's edge),
    its horizontal run measured along world ``axis`` (0: x, 2: z; y is up)."""

    def __init__(self, clamp, tip, axis, steps, target=0.0, scale=1.0):
        super().__init__(steps, target, scale)
        self.clamp = int(_ids("clamp", clamp, 1)[0])
        self.tip = _ids("tip", tip, 1)
        if axis not in (0, 2):
            raise SceneError(f"axis must be 0 (x) or 2 (z), horizontal (got {axis!r})")
        self.axis = axis

    def measure(self, x):
        d = x[self.tip].mean(axis=0) - x[self.clamp]
        run = d[self.axis]
        r2 = run * run + d[1] * d[1]
        g_tip = np.zeros(3)
        g_tip[1] = -abs(run) / r2
        g_tip[self.axis] = d[1] / r2 * np.sign(run)
        g = np.zeros_like(x)
        g[self.tip] = g_tip / len(self.tip)
        g[self.clamp] -= g_tip
        return float(np.degrees(np.arctan2(-d[1], abs(run)))), np.degrees(g)


class DrapeCoefficient(Measured):
    """Cusick's drape coefficient (A_shadow - A_support) / (A_disc - A_support) of a disc
    of ``radius`` on a support of radius ``support`` (m), the shadow the area inside its
    projected rim (``rim``: particle ids in angular order; the shoelace formula on the
    horizontal x, z plane): the rasterised shadow's area where no fold hangs out over the
    rim, and differentiable."""

    def __init__(self, rim, radius, support, steps, target=0.0, scale=0.01):
        super().__init__(steps, target, scale)
        self.rim = _ids("rim", rim, 3)
        self.radius = as_scalar("radius", radius, minimum=0.0, strict=True)
        self.support = as_scalar("support", support, minimum=0.0, strict=True)
        if self.support >= self.radius:
            raise SceneError(f"support must be less than radius {self.radius:g} m (got "
                             f"{self.support:g})")

    def measure(self, x):
        p = x[self.rim][:, [0, 2]]
        after, before = np.roll(p, -1, axis=0), np.roll(p, 1, axis=0)
        area = 0.5 * float((p[:, 0] * after[:, 1] - after[:, 0] * p[:, 1]).sum())
        sign = 1.0 if area > 0 else -1.0
        ring = np.pi * (self.radius ** 2 - self.support ** 2)
        g = np.zeros_like(x)
        g[self.rim, 0] = sign * 0.5 * (after[:, 1] - before[:, 1]) / ring
        g[self.rim, 2] = sign * 0.5 * (before[:, 0] - after[:, 0]) / ring
        return (abs(area) - np.pi * self.support ** 2) / ring, g
