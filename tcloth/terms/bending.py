"""Bending with linear stiffness: Bergou, Wardetzky, Harmon, Zorin & Grinspun 2006, "A
quadratic bending model for inextensible surfaces".

Provot's flexion springs join each grid particle to the next but one along each grid line,
two spacings h apart; a fold by phi shortens one only to second order, 2h cos(phi/2) =
2h (1 - phi^2/8), so its energy is quartic in the angle and a flat cloth has no bending
stiffness at small curvature. This term gives the cloth a bending rigidity B (N m),
energy B/2 kappa^2 per area for a curvature kappa.

Each interior edge (x0, x1) of a cloth's triangles with the opposite vertices x2, x3 of its
two triangles is a hinge. With the cotangents c_jk of the rest angles between the hinge's
edges e0 = x1 - x0, e1 = x2 - x0, e2 = x3 - x0, e3 = x2 - x1, e4 = x3 - x1, the weights

    K = (c03 + c04, c01 + c02, -c01 - c03, -c02 - c04)

make s = sum_i K_i x_i vanish on the flat rest hinge (and on every rigid motion of it),
and |s| = 2 |e0| sin(theta / 2) when the hinge folds by theta keeping its edge lengths.
The hinge's energy is

    U = B_e / (2 A_e) |s|^2,   A_e the rest area of its two triangles,

quadratic in the positions: its Hessian (B_e / A_e) K K^T (x) I is constant, which is what
makes it cheap in the implicit solvers (Bergou's point). The scale B_e / A_e is measured,
not assumed: summed over a grid or an equilateral mesh bent into a cylinder of curvature
kappa it gives B/2 kappa^2 per area as the resolution grows (tests/test_bending.py;
Bergou's Q_e = 3/A_e K K^T is for the integral of the squared mean curvature).

A grid's triangles have their diagonals all one way, and on them a hinge across a cell
side sees kappa_xx - kappa_xy: bending could trade against twist, and a narrow strip would
bend 30-90 % too easily. A grid cloth's hinges are therefore the cell sides of both
diagonal triangulations, each with half the rigidity (no diagonal hinges): the two see
kappa_xx -+ kappa_xy, so the energy is B/2 (kappa_xx^2 + kappa_yy^2 + 2 kappa_xy^2) per area,
an isotropic plate with Poisson's ratio 0, for every deformation. Hinges across a side
along j (constant i) take the warp rigidity (they bend the cloth along i), those along i
the weft. A mesh cloth's hinges are its interior edges, with one rigidity (on an
equilateral mesh a plate with Poisson's ratio 1/3).

The model needs a flat rest shape (a hinge folded at rest would be pulled flat):
``Scene.set_bending`` refuses a cloth whose rest hinges are folded. Each hinge stores
c = sqrt(B_e / A_e) K, so U = |sum c_i x_i|^2 / 2 and the force on its vertex i is -c_i s.
Backward Euler, VBD and projective dynamics take the exact constant Hessian; XPBD takes a
hinge as the compliant vector constraint s = 0.
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..features.bending import BENDING
from ..runtime import serial
from .base import ColouredConstraints, ConstantMatrix, Term, add_or_set


@ti.data_oriented
class Bending(Term, ConstantMatrix, ColouredConstraints):
    """The hinges of the scene's bending cloths (``Scene.set_bending``); for XPBD
    (``constraints=True``) each a vector constraint (``project_constraint``)."""
    name = "bending"
    feature = BENDING
    implicit = "potential"
    projective = "force"
    provides = frozenset({"couplings", "local_system", "constant_matrix", "constraints"})
    options = {"constraints": False}

    @staticmethod
    def present(model):
        return model.bending is not None and model.bending.count > 0

    def __init__(self, model, constraints=False):
        bending = model.bending
        self.hinges, self.weights = bending.hinges, bending.weights
        self.start, self.entries = bending.start, bending.entries
        self.diagonal = bending.diagonal
        self.s = ti.Vector.field(3, runtime.real(), shape=self.hinges.shape[0])
        if constraints:
            self.inv_mass = model.inv_mass
            self.constraints_begin(self.hinges.to_numpy(), model.particle_count, 3)

    @ti.func
    def project_constraint(self, x, x_prev, h, k):
        """Hinge k as the vector constraint s = sum_i c_i x_i = 0 with compliance 1
        (its energy is |s|^2 / 2): alpha = 1 / h^2, grad_i s = c_i I."""
        ids, c = self.hinges[k], self.weights[k]
        s = self.hinge_vector(k, x)
        alpha = 1.0 / (h * h)
        denominator = alpha
        for i in ti.static(range(4)):
            denominator += self.inv_mass[ids[i]] * c[i] * c[i]
        dlam = (-s - alpha * self.lam[k]) / denominator
        for i in ti.static(range(4)):
            x[ids[i]] += self.inv_mass[ids[i]] * c[i] * dlam
        self.lam[k] += dlam

    def batch_obstacle(self):
        if not serial(self.hinges):
            return f"the bending's {self.hinges.shape[0]} hinges run on several threads"
        return None

    def constant_matrix(self):
        """Projective dynamics' constant part: the Hessian itself, sum over hinges of
        c c^T (x) I (``diagonal``, ``add_product``)."""
        return self

    def coupled_pairs(self):
        """(M,2) particle pairs that share a hinge (for graph colourings), NumPy."""
        ids = self.hinges.to_numpy().astype(np.int64)
        return np.concatenate([ids[:, [i, j]] for i in range(4) for j in range(i + 1, 4)])

    @ti.func
    def hinge_vector(self, k, x):
        """s = sum_i c_i x_i of hinge k."""
        ids, c = self.hinges[k], self.weights[k]
        return (c[0] * x[ids[0]] + c[1] * x[ids[1]]) + (c[2] * x[ids[2]] + c[3] * x[ids[3]])

    @ti.func
    def hinge_vectors(self, x):
        """Every hinge's s at x into ``s``."""
        ti.loop_config(serialize=ti.static(serial(self.hinges)))
        for k in range(self.hinges.shape[0]):
            self.s[k] = self.hinge_vector(k, x)

    @ti.func
    def gather(self, p):
        """sum over particle p's hinges of c_p s (after ``hinge_vectors``): its gradient."""
        g = ti.Vector.zero(float, 3)
        for e in range(self.start[p], self.start[p + 1]):
            k, slot = self.entries[e][0], self.entries[e][1]
            g += self.weights[k][slot] * self.s[k]
        return g

    @ti.func
    def accumulate(self, x, v, t, f_out):
        """f_out -= the energy's gradient, gathered per particle (no atomics)."""
        self.hinge_vectors(x)
        ti.loop_config(serialize=ti.static(serial(f_out)))
        for p in range(f_out.shape[0]):
            f_out[p] -= self.gather(p)

    @ti.func
    def local_system(self, p, x, x0, h):
        """(gradient, Hessian block) of particle p at x, each of its hinges evaluated
        afresh (VBD's Gauss-Seidel sweeps move its neighbours between calls); x0 and h
        are unused (the energy is conservative)."""
        g = ti.Vector.zero(float, 3)
        for e in range(self.start[p], self.start[p + 1]):
            k, slot = self.entries[e][0], self.entries[e][1]
            g += self.weights[k][slot] * self.hinge_vector(k, x)
        return g, self.diagonal_block(p)

    @ti.func
    def local_energy(self, p, x, x0, h):
        """The energy of particle p's hinges at x, sum of |s|^2 / 2 (as a function of x[p]
        alone, the energy up to a constant)."""
        e = 0.0
        for k in range(self.start[p], self.start[p + 1]):
            s = self.hinge_vector(self.entries[k][0], x)
            e += 0.5 * s.dot(s)
        return e

    @ti.kernel
    def _energy(self, x: ti.template(), out: ti.template()) -> ti.f64:
        out[0] = 0
        ti.loop_config(serialize=ti.static(serial(self.hinges)))
        for k in range(self.hinges.shape[0]):
            s = self.hinge_vector(k, x)
            out[0] += ti.cast(0.5 * s.dot(s), out.dtype)
        return ti.cast(out[0], ti.f64)

    def energy(self, x, t, out):
        """sum over hinges of |s|^2 / 2, in the accumulator's type."""
        return self._energy(x, out)

    # -- backward Euler, VBD, projective ------------------------------------------------------
    @ti.kernel
    def _incremental(self, x: ti.template(), with_grad: ti.template(), acc: ti.template(),
                     grad: ti.template()):
        self.hinge_vectors(x)
        ti.loop_config(serialize=ti.static(serial(self.hinges)))
        for k in range(self.hinges.shape[0]):
            e = 0.5 * self.s[k].dot(self.s[k])
            acc[0] += ti.cast(e, acc.dtype)
            acc[1] += ti.cast(e, acc.dtype)
        if ti.static(with_grad):
            ti.loop_config(serialize=ti.static(serial(grad)))
            for p in range(grad.shape[0]):
                grad[p] += self.gather(p)

    def add_incremental(self, x, x0, h, with_grad, acc, grad):
        """acc[0] += the energy at x (acc[1] its magnitude); with_grad: grad += its
        gradient. It is conservative: nothing of it depends on x0 or h."""
        self._incremental(x, with_grad, acc, grad)

    def prepare_blocks(self, x, x0, h):
        """Nothing: the Hessian is constant."""

    @ti.func
    def diagonal_block(self, p):
        return self.diagonal[p] * ti.Matrix.identity(float, 3)

    @ti.kernel
    def _couplings(self, v: ti.template(), out: ti.template(), first: ti.template()):
        self.hinge_vectors(v)
        ti.loop_config(serialize=ti.static(serial(out)))
        for p in range(out.shape[0]):
            add_or_set(out, p, self.gather(p) - self.diagonal[p] * v[p], first)

    def add_product(self, v, out, first):
        """out += (= when ``first``) the Hessian without its diagonal blocks times v."""
        self._couplings(v, out, first)
