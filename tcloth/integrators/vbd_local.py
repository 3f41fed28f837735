"""A vertex's own problem in VBD (``vbd.py``): E as a function of that vertex alone, the
line search on it where a Newton step can bring a contact row into contact, and the
vertex's gradient and block read out for tests.

Why a line search. The self-contact penalty k/2 (T - d)^2 is zero beyond the thickness T
and has stiffness k within it, so its Hessian jumps there, and k is hundreds of times a
vertex's inertia m/h^2 (400 N/m against 0.9 to 1.7 N/m in ``tools/bench_sliding.py``'s
case). A vertex just out of contact has no contact in its Newton model: its step, set
by inertia, gravity and the springs, can carry it millimetres into a dozen rows at once
and raise its part of E 250-fold. Its next step takes it back out, and the iterations
cycle at the thickness instead of converging (``docs/contact.md``, "VBD converges to
backward Euler's step in contact").

How. A row's distance moves at most as far as any of its particles (a point of a
triangle or an edge moves at most as far as the vertex that moves it), so a step shorter
than the vertex's clearance (the least d - T over its rows out of contact,
``SelfContact.vertex_system``) brings no row in and is taken as it is. A longer one is
deferred to the end of the sweep (``deferred_pass``, one thread, in colour order), where
the vertex's step is computed again and, if still longer than its clearance, halved
until E restricted to the vertex falls by Armijo's fraction of its first-order decrease,
at most TRIALS times; where none does, the vertex stays. Every update that can cross the
thickness is then a descent step on E. Deferring keeps the line search's code out of
the colours' unrolled loops (compiled once, not once per colour), and a sweep that
defers nothing is the plain one.
"""
import numpy as np
import taichi as ti

from ..terms import springs as spring_term

# halvings of a step that fails the check: the last one tried is 2^-(TRIALS - 1) of it
TRIALS = 8
# Armijo's constant: a step s passes where E falls by at least this times -g . s
ARMIJO = 1e-4


@ti.data_oriented
class VertexLocal:
    """The per-vertex parts of VBD (the module docstring), for a class with VBD's fields,
    terms and ``_local``."""

    @ti.func
    def deferred_pass(self, x, h, t):
        """The updates deferred by this sweep's colour passes (``deferred``), one after
        another in colour order, each searched along where it can still bring a row into
        contact."""
        ti.loop_config(serialize=True)
        for k in range(self.order.shape[0]):
            p = self.order[k]
            if self.deferred[p]:
                self.deferred[p] = 0
                g, block, clearance = self._local(p, x, h, t)
                step = -(block.inverse() @ g)
                if step.norm() >= clearance:
                    step = self._searched(p, x, h, t, g, step)
                x[p] = self._bounded(p, x[p] + step)

    @ti.func
    def _searched(self, p, x, h, t, g, step):
        """``step`` (vertex p's Newton step at x, its gradient g) halved until E
        restricted to p falls by ARMIJO times -g . step at least, or zero where none of
        TRIALS does; x[p] is left as it was. The first pass evaluates E at the start (one
        copy of the energy's code)."""
        start = x[p]
        slope = g.dot(step)
        e0, scale = 0.0, 0.0
        trial, found = 0, False
        while trial <= TRIALS and not found:
            x[p] = start + scale * step
            e = self._vertex_energy(p, x, h, t) + self._held_model(p, scale * step)
            if trial == 0:
                e0, scale = e, 1.0
            elif e <= e0 + ARMIJO * scale * slope:
                found = True
            else:
                scale *= 0.5
            trial += 1
        x[p] = start
        return scale * step if found else ti.Vector.zero(float, 3)

    @ti.func
    def _vertex_energy(self, p, x, h, t):
        """E at x as a function of x[p] alone, up to a constant: its inertia, its
        particle terms and lagged forces, its springs, and its parts of the coupled terms
        that VBD evaluates afresh (bending, the membrane, self-contact)."""
        e_x = self.potential
        d = x[p] - e_x.x_hat[p]
        e = 0.5 * self.mass[p] / (h * h) * d.dot(d)
        for term in ti.static(e_x.particle_terms):
            e_t, _magnitude, _g = term.incremental(p, x, e_x.x0, h, t)
            e += e_t
        if ti.static(e_x.has_lagged):
            e -= e_x.f_lag[p].dot(x[p])
        for term in ti.static(self.local_terms):
            e += term.local_energy(p, x, e_x.x0, h)
        for term in ti.static(self.vertex_terms):
            e += term.vertex_energy(p, x, e_x.x0, h)
        if ti.static(self.has_springs):
            d0 = ti.static(self.springs.d0)
            for a in range(self.adj_start[p], self.adj_start[p + 1]):
                s, q = self.adj[a][0], self.adj[a][1]
                sign = 1.0 if self.pairs[s][0] == p else -1.0
                e_s, _g_s = spring_term.incremental(x[p], x[q], e_x.x0[p], e_x.x0[q],
                                                    sign * d0[s], self.ks[s], self.kd[s],
                                                    self.rest[s], h)
                e += e_s
        return e

    @ti.func
    def _held_model(self, p, s):
        """The change, for a move s of vertex p, of the quadratic model VBD steps on for
        the terms it holds through an iteration (pressure): their gradient and blocks."""
        change = 0.0
        if ti.static(bool(self.pair_terms)):
            block = ti.Matrix.zero(float, 3, 3)
            for term in ti.static(self.pair_terms):
                block += term.diagonal_block(p)
            change = self.contact_grad[p].dot(s) + 0.5 * s.dot(block @ s)
        return change

    def local_system(self, x, h, t, p):
        """(g_i, H_i) of vertex p at positions x (a field) within the step begun last, as
        NumPy; for tests."""
        self._contacts(x, h)
        out = np.asarray(self._local_kernel(x, h, t, p, self._layout()))
        return out[0], out[1:]

    @ti.kernel
    def _local_kernel(self, x: ti.template(), h: float, t: float, p: ti.i32,
                      layout: ti.template()) -> ti.types.matrix(4, 3, ti.f64):
        g, block, _clearance = self._local(p, x, h, t)
        out = ti.Matrix.zero(ti.f64, 4, 3)
        for j in ti.static(range(3)):
            out[0, j] = g[j]
            for i in ti.static(range(3)):
                out[1 + i, j] = block[i, j]
        return out
