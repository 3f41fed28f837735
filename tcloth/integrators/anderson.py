"""Anderson acceleration of a fixed-point iteration x <- G(x) (Walker & Ni 2011; for
projective dynamics, Peng, Deng, Zhang & Liu 2018, "Anderson Acceleration for Geometry
Optimization and Physics Simulation").

After the plain iteration has taken x_k to G(x_k), the next iterate is the combination of
the last m + 1 maps' outputs whose residuals f = G(x) - x combine to the least norm:

    x_{k+1} = G(x_k) - sum_j gamma_j dG_j,
    gamma = argmin |f_k - sum_j gamma_j dF_j|,

dF_j and dG_j the differences of successive residuals and outputs. Liu's local/global
iteration converges linearly, slowest where springs are compressed or bent (the constant
matrix is far from the Hessian there); the combination is a secant method on its history,
which takes the slow directions out. A fixed point of G is one of the accelerated
iteration, so the step it converges to is the plain iteration's (the backward Euler
step). The safeguard is a restart: where |g|^2, the force residual's square, at an
accelerated iterate is more than GROWTH times the one before it, the history is dropped
and the iteration goes on from that iterate plainly (``restarts`` counts them in the
step). A restart wherever it grew at all dropped the history in one iteration of six on
a cloth draping over a sphere at one step per frame and converged less (docs/realtime.md).
"""
import taichi as ti

from .. import runtime
from ..errors import SceneError
from ..runtime import serial

# the least-squares problem's Tikhonov weight, relative to its Gram matrix's trace
REGULARISATION = 1e-10
# a restart where |g|^2 grows by more than this factor in one iteration
GROWTH = 10.0


def check_depth(depth):
    """The option ``anderson``: an int >= 0 (0: off)."""
    if not (isinstance(depth, int) and not isinstance(depth, bool) and depth >= 0):
        raise SceneError(f"projective's anderson must be an int >= 0, the history's "
                         f"length (got {depth!r})")
    return depth


@ti.data_oriented
class Anderson:
    """The history of ``depth`` differences for ``n`` particles' positions.

    Call ``start()`` at each step's start; after each plain iteration, which moved x from
    its input (copied to ``before`` by ``keep``) to G(x), ``mix(x, v, x0, h, residual)``
    (``residual``: |g|^2 at the iteration's input) sets x to the accelerated iterate and
    v = (x - x0) / h.
    """

    def __init__(self, n, depth):
        real = runtime.real()
        self.depth = depth
        self.before, self.f_last, self.g_last = (ti.Vector.field(3, real, shape=n)
                                                 for _ in range(3))
        self.d_f, self.d_g = (ti.Vector.field(3, real, shape=(depth, n)) for _ in range(2))
        self.gram = ti.field(ti.f64, shape=(depth, depth + 1))
        self.gamma = ti.field(ti.f64, shape=depth)
        self.count = self.slot = self.restarts = 0
        self.last_residual = None

    def start(self):
        self.count = self.slot = self.restarts = 0
        self.last_residual = None

    @ti.kernel
    def keep(self, x: ti.template()):
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            self.before[p] = x[p]

    def mix(self, x, v, x0, h, residual):
        restart = self.count > 0 and residual > GROWTH * self.last_residual
        if restart:
            self.count = self.slot = 0
            self.restarts += 1
        stored = self.last_residual is not None and not restart
        self.last_residual = residual
        self._differences(x, self.slot, stored)
        if stored:
            self.slot = (self.slot + 1) % self.depth
            self.count = min(self.count + 1, self.depth)
        if self.count == 0:
            return
        self._accelerate(x, v, x0, h, self.count)

    @ti.kernel
    def _differences(self, x: ti.template(), slot: ti.i32, stored: ti.i32):
        """f = G(x_k) - x_k with G(x_k) in x; the differences from the last iteration's
        into ``slot``; f and G(x_k) kept for the next."""
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            f = x[p] - self.before[p]
            if stored:
                self.d_f[slot, p] = f - self.f_last[p]
                self.d_g[slot, p] = x[p] - self.g_last[p]
            self.f_last[p] = f
            self.g_last[p] = x[p]

    @ti.kernel
    def _accelerate(self, x: ti.template(), v: ti.template(), x0: ti.template(), h: float,
                    count: ti.i32):
        """The normal equations dF^T dF gamma = dF^T f_k (one thread an entry of the
        Gram matrix, summing over the particles), regularised, solved by Gaussian
        elimination (count <= depth unknowns, one thread), and the combination."""
        for a, b in ti.ndrange(count, count + 1):
            total = ti.cast(0.0, ti.f64)
            for p in range(self.f_last.shape[0]):
                other = self.f_last[p]
                if b < count:
                    other = self.d_f[b, p]
                total += ti.cast(self.d_f[a, p].dot(other), ti.f64)
            self.gram[a, b] = total
        ti.loop_config(serialize=True)
        for _ in range(1):
            trace = ti.cast(0.0, ti.f64)
            for a in range(count):
                trace += self.gram[a, a]
            for a in range(count):
                self.gram[a, a] += ti.max(REGULARISATION * trace, 1e-30)
            for a in range(count):
                for r in range(a + 1, count):
                    factor = self.gram[r, a] / self.gram[a, a]
                    for c in range(a, count + 1):
                        self.gram[r, c] -= factor * self.gram[a, c]
            for i in range(count):
                a = count - 1 - i
                value = self.gram[a, count]
                for c in range(a + 1, count):
                    value -= self.gram[a, c] * self.gamma[c]
                self.gamma[a] = value / self.gram[a, a]
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            y = self.g_last[p]
            for a in range(count):
                y -= ti.cast(self.gamma[a], float) * self.d_g[a, p]
            x[p] = y
            v[p] = (y - x0[p]) / h
