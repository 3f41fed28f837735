"""Geometric multigrid on one cloth grid, for the implicit integrators' linear systems.

A matrix on a cloth grid couples each particle with the ends of its springs: on a Provot
grid, a stencil of 13 points (itself, 4 structural, 4 shear, 4 flexion neighbours). It is
stored per node as stencil weights, with pinned particles filtered out (their rows and
columns are 0, so they never move). Coarser levels halve the grid in both directions
(nodes 2I of the finer level) with bilinear prolongation P (an even-sized grid gets a
coarse node one past its end) and Galerkin operators A_c = P^T A P, which stay within a
5 x 5 stencil (21 points for Provot cloth). Each coarse weight is a fixed combination of
fine weights (``galerkin_terms``). The coarsest level (64 nodes or fewer) is solved
exactly with its dense inverse (Gauss-Jordan in a kernel).

Two matrices, two cycles, one hierarchy (``GridLevels``):
  - ``GridMultigrid``: the projective solver's constant matrix, the same for x, y and z
    (scalar weights), built once per scene in NumPy; the fine level's diagonal may differ
    between x, y and z at the iterate (``set_fine_diagonal``: the colliders' stiffness
    along their normals, n n^T's diagonal). One weighted Jacobi sweep before and
    one after each coarse correction (weight 4/3 over the largest eigenvalue of D^-1 A),
    the first folded into the restriction.
  - ``BlockGridMultigrid``: backward Euler's Newton Hessian (symmetric 3 x 3 blocks),
    built in kernels: the fine level at every Newton iteration, the coarse levels at each
    step's first (``build``). Block Gauss-Seidel sweeps, forwards before and backwards
    after each coarse correction: no weight to estimate, and convergent for any symmetric
    positive definite matrix. On one thread the nodes go in order; in parallel in nine
    colours.
Either V-cycle is a symmetric positive definite approximation B of A^-1 with the
spectrum of B A in (0, 1]: a preconditioner for conjugate gradients (``GridPCG``), or an
update that decreases the energy a linear solve would minimise.

Vectors are vec3 fields padded by two nodes of zeros on every side, so that stencils need
no bounds tests. The scalar cycle's loops are ``ti.func`` bodies called from the projective
solver's kernel, so that a whole iteration is one launch; the block cycle is small kernels
(they compile faster than one large kernel): on one thread four for the fine level and
two for the coarse ones, in parallel a few per level. ``vcycle`` runs one from NumPy for
tests and tools.
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..runtime import serial
from ..errors import SceneError
from . import linalg
from .galerkin import (COARSEST_NODES, PAD, coarse_size, coarse_stencil, dense_matrix, galerkin,
                       smoothing_weight)


@ti.data_oriented
class GridLevels:
    """The levels of an (ny, nx) grid for a matrix on ``stencil`` (a tuple of (di, dj)
    offsets): padded vectors per level, restriction, prolongation and the coarsest solve.
    Subclasses give the matrix (``product_at``, ``_active``), how a level's solution starts
    (``_begin_level``), where it ends (``_solution``) and the cycle."""

    def __init__(self, nx, ny, stencil):
        real = runtime.real()
        self.stencil = tuple(stencil)
        self.shapes = [(ny, nx)]
        while self.shapes[-1][0] * self.shapes[-1][1] > COARSEST_NODES:
            cy, cx = self.shapes[-1]
            self.shapes.append((coarse_size(cy), coarse_size(cx)))
        self.stencils = [self.stencil]
        for _ in self.shapes[1:]:
            self.stencils.append(coarse_stencil(self.stencils[-1]))
        self.serial = runtime.serial_count(nx * ny)

        def padded():
            return [ti.Vector.field(3, real, shape=(sy + 2 * PAD, sx + 2 * PAD))
                    for sy, sx in self.shapes]
        # e: the level's solution; r: its right-hand side; t: residual on the way down,
        # and the coarsest level's solution
        self.e, self.r, self.t = padded(), padded(), padded()
        n = 3 * self.shapes[-1][0] * self.shapes[-1][1]
        # the coarsest level's dense matrix, inverted in place (``_invert_coarsest``)
        self.coarsest_inverse = ti.field(real, shape=(n, n))

    @property
    def levels(self):
        return len(self.shapes)

    def _set_coarsest(self, dense):
        """The coarsest level's inverse from its dense (3 nc, 3 nc) NumPy matrix (rows and
        columns 3 (J * nx + I) + component; those of inactive nodes 0)."""
        self.coarsest_inverse.from_numpy(dense.astype(runtime.numpy_real()))
        self._invert_coarsest_kernel()

    @ti.kernel
    def _invert_coarsest_kernel(self):
        self._invert_coarsest()

    @ti.func
    def _invert_coarsest(self):
        """coarsest_inverse = its inverse, in place, by Gauss-Jordan elimination without
        pivoting: the matrix is symmetric positive definite on its active rows (positive
        diagonal), so every pivot is positive. Inactive rows and columns are 0 and stay 0."""
        a = ti.static(self.coarsest_inverse)
        n = ti.static(a.shape[0])
        ti.loop_config(serialize=True)
        for k in range(n):
            if a[k, k] > 0.0:
                pivot = 1.0 / a[k, k]
                a[k, k] = 1.0
                for c in range(n):
                    a[k, c] *= pivot
                for r in range(n):
                    if r != k:
                        f = a[r, k]
                        a[r, k] = 0.0
                        for c in range(n):
                            a[r, c] -= f * a[k, c]

    @ti.func
    def _restrict(self, level: ti.template()):
        """r_{l+1} = P^T t_l (t_l is 0 outside the grid); the next level's solution starts."""
        cy, cx = ti.static(self.shapes[level + 1])
        t = ti.static(self.t[level])
        ti.loop_config(serialize=ti.static(self.serial))
        for J, I in ti.ndrange(cy, cx):
            j, i = 2 * J + PAD, 2 * I + PAD
            r = (t[j, i] + 0.5 * (t[j, i - 1] + t[j, i + 1] + t[j - 1, i] + t[j + 1, i])
                 + 0.25 * (t[j - 1, i - 1] + t[j - 1, i + 1] + t[j + 1, i - 1] + t[j + 1, i + 1]))
            self.r[level + 1][J + PAD, I + PAD] = r
            self._begin_level(level + 1, J, I, r)

    @ti.func
    def _solve_coarsest(self):
        last = ti.static(self.levels - 1)
        cy, cx = ti.static(self.shapes[last])
        ti.loop_config(serialize=ti.static(self.serial))
        for J, I in ti.ndrange(cy, cx):
            row = 3 * (J * cx + I)
            acc = ti.Vector.zero(float, 3)
            for q in range(cy * cx):
                rq = self.r[last][q // cx + PAD, q % cx + PAD]
                for a in ti.static(range(3)):
                    for b in ti.static(range(3)):
                        acc[a] += self.coarsest_inverse[row + a, 3 * q + b] * rq[b]
            self.t[last][J + PAD, I + PAD] = acc

    @ti.func
    def _prolong(self, level: ti.template()):
        """e_l += P (the solution of level l + 1) on active nodes, coarse node by coarse node:
        fine (2J, 2I) and the three between it and the next coarse nodes."""
        fy, fx = ti.static(self.shapes[level])
        tc, e = ti.static(self._solution(level + 1), self.e[level])
        ti.loop_config(serialize=ti.static(self.serial))
        for J, I in ti.ndrange((fy + 1) // 2, (fx + 1) // 2):
            c00, c01 = tc[J + PAD, I + PAD], tc[J + PAD, I + 1 + PAD]
            c10, c11 = tc[J + 1 + PAD, I + PAD], tc[J + 1 + PAD, I + 1 + PAD]
            fine = ti.Matrix.rows([c00, 0.5 * (c00 + c01), 0.5 * (c00 + c10),
                                   0.25 * (c00 + c01 + c10 + c11)])
            for a in ti.static(range(2)):
                for b in ti.static(range(2)):
                    j, i = 2 * J + a, 2 * I + b
                    if j < fy and i < fx:
                        if self._active(level, j, i):
                            e[j + PAD, i + PAD] += ti.Vector([fine[2 * a + b, c]
                                                              for c in range(3)])

    @ti.func
    def result(self, j, i):
        """The cycle's correction at fine node (j, i)."""
        return ti.static(self._solution(0))[j + PAD, i + PAD]

    @ti.kernel
    def _load_rhs(self):
        ny, nx = ti.static(self.shapes[0])
        ti.loop_config(serialize=ti.static(self.serial))
        for j, i in ti.ndrange(ny, nx):
            self.set_rhs(j, i, self.t[0][j + PAD, i + PAD])

    def load_rhs(self, r):
        """``set_rhs`` at every fine node from a (ny, nx, 3) NumPy array (for tests and
        tools)."""
        padded = np.pad(r, ((PAD, PAD), (PAD, PAD), (0, 0)))
        self.t[0].from_numpy(padded.astype(runtime.numpy_real()))
        self._load_rhs()

    def vcycle(self, r):
        """One V-cycle on a (ny, nx, 3) NumPy right-hand side: B r (for tests and tools)."""
        self.load_rhs(r)
        self._run_cycle()
        return self._solution(0).to_numpy()[PAD:-PAD, PAD:-PAD]


@ti.data_oriented
class GridMultigrid(GridLevels):
    """V-cycles for A e = r with A the same scalar matrix for x, y and z, given by
    ``set_matrix`` as fine stencil weights (ny, nx, len(stencil)); weighted Jacobi
    smoothing. ``varied``: the fine diagonal may take additions per component at the
    iterate (``set_fine_diagonal``); without, the fine product skips them."""

    def __init__(self, nx, ny, stencil, varied=False):
        super().__init__(nx, ny, stencil)
        self.varied = varied
        real = runtime.real()
        self.w = [ti.Vector.field(len(s), real, shape=shape)
                  for s, shape in zip(self.stencils, self.shapes)]
        # per component: the fine level's diagonal differs between x, y and z where
        # ``set_fine_diagonal`` adds a contact's stiffness along its normal
        self.inv_diag = [ti.Vector.field(3, real, shape=shape) for shape in self.shapes]
        self.omega = ti.field(real, shape=len(self.shapes))
        self.fine_base = ti.field(real, shape=self.shapes[0])
        self.fine_extra = ti.Vector.field(3, real, shape=self.shapes[0] if varied else (1, 1))

    def set_matrix(self, weights, omegas=None):
        """Fine stencil weights (ny, nx, len(stencil)); builds every level. ``omegas``: the
        levels' Jacobi weights to keep (those a matrix with no larger a diagonal got:
        adding to the diagonal keeps them convergent), else computed. Returns them."""
        npr = runtime.numpy_real()
        computed = []
        for level, stencil in enumerate(self.stencils):
            diag = weights[..., stencil.index((0, 0))]
            self.w[level].from_numpy(weights.astype(npr))
            inverse = np.where(diag > 0, 1.0 / np.where(diag > 0, diag, 1.0), 0.0)
            self.inv_diag[level].from_numpy(np.repeat(inverse[..., None], 3, -1).astype(npr))
            if omegas is None:
                computed.append(smoothing_weight(weights, stencil))
            if level + 1 < self.levels:
                weights = galerkin(weights, stencil)
        self.fine_extra.fill(0)
        omegas = computed if omegas is None else omegas
        self.omega.from_numpy(np.array(omegas, dtype=npr))
        self._set_coarsest(np.kron(dense_matrix(weights, self.stencils[-1]), np.eye(3)))
        return omegas

    def set_fine_base(self, centre):
        """The fine level's diagonal (ny, nx) before ``set_fine_diagonal``'s additions."""
        self.fine_base.from_numpy(centre.astype(runtime.numpy_real()))

    @ti.func
    def set_fine_diagonal(self, j, i, extra):
        """The fine level's diagonal at node (j, i): its ``set_fine_base`` value plus the
        vector extra, per component (an active node's only; before the node's
        ``set_rhs``; only where built ``varied``). The coarse levels keep what
        ``set_matrix`` gave them."""
        d = self.fine_base[j, i]
        if d > 0.0:
            self.fine_extra[j, i] = extra
            self.inv_diag[0][j, i] = 1.0 / (d + extra)

    def _solution(self, level):
        return self.t[level]

    @ti.func
    def _active(self, level: ti.template(), j, i):
        return self.inv_diag[level][j, i][0] > 0.0

    @ti.func
    def product_at(self, level: ti.template(), v: ti.template(), j, i):
        """(A_level v) at node (j, i) (unpadded indices) of a padded field v."""
        acc = ti.Vector.zero(float, 3)
        w = self.w[level][j, i]
        for k in ti.static(range(len(self.stencils[level]))):
            di, dj = ti.static(self.stencils[level][k])
            acc += w[k] * v[j + PAD + dj, i + PAD + di]
        if ti.static(level == 0 and self.varied):
            acc += self.fine_extra[j, i] * v[j + PAD, i + PAD]
        return acc

    @ti.func
    def _begin_level(self, level: ti.template(), j, i, r):
        """The level's first Jacobi sweep from 0."""
        self.e[level][j + PAD, i + PAD] = self.omega[level] * self.inv_diag[level][j, i] * r

    @ti.func
    def set_rhs(self, j, i, rhs):
        """The finest level's right-hand side at node (j, i), and its first Jacobi sweep
        from 0."""
        self.r[0][j + PAD, i + PAD] = rhs
        self._begin_level(0, j, i, rhs)

    @ti.func
    def cycle(self):
        """The rest of a V-cycle after ``set_rhs`` at every fine node; the correction ends
        in ``result``."""
        last = ti.static(self.levels - 1)
        for level in ti.static(range(last)):
            ny, nx = ti.static(self.shapes[level])
            ti.loop_config(serialize=ti.static(self.serial))
            for j, i in ti.ndrange(ny, nx):      # residual of the pre-smoothed solution
                self.t[level][j + PAD, i + PAD] = (self.r[level][j + PAD, i + PAD]
                                                   - self.product_at(level, self.e[level], j, i))
            self._restrict(level)
        self._solve_coarsest()
        for level in ti.static(range(last - 1, -1, -1)):
            self._prolong(level)
            self._smooth(level)

    @ti.kernel
    def _run_cycle(self):
        self.cycle()

    @ti.func
    def _smooth(self, level: ti.template()):
        """t_l = e_l + omega D^-1 (r_l - A e_l)."""
        fy, fx = ti.static(self.shapes[level])
        ti.loop_config(serialize=ti.static(self.serial))
        for j, i in ti.ndrange(fy, fx):
            self.t[level][j + PAD, i + PAD] = (
                self.e[level][j + PAD, i + PAD] + self.omega[level] * self.inv_diag[level][j, i]
                * (self.r[level][j + PAD, i + PAD] - self.product_at(level, self.e[level], j, i)))


def single_grid(model, linear_solver):
    """The cloth grid a multigrid solves on, for the option ``linear_solver``: "auto"
    (the grid when it is the whole scene, else None), "multigrid" (that grid, or
    SceneError) or "cg" (None)."""
    if linear_solver not in ("auto", "multigrid", "cg"):
        raise SceneError("linear_solver must be 'auto', 'multigrid' or 'cg' "
                         f"(got {linear_solver!r})")
    grid = model.single_grid()
    if linear_solver == "multigrid" and grid is None:
        raise SceneError("linear_solver='multigrid' needs a scene that is one cloth grid "
                         "and nothing else (no other particles or springs)")
    return grid if linear_solver in ("auto", "multigrid") else None


@ti.data_oriented
class MultigridPCG(linalg.PCG):
    """``linalg.PCG``'s conjugate gradients on the adjacency matrix of a scene that is one
    cloth grid (particle p = j nx + i), preconditioned by a V-cycle of ``mg`` (a
    ``GridMultigrid``) instead of A's diagonal: projective dynamics' global solve where
    colliders change A's diagonal at every iterate, which one V-cycle alone solves poorly
    (a stiff point on the fine level is smeared by the coarse levels' interpolation)."""

    def __init__(self, mg, n, diag, weights, adj_start, adj, inv_mass, couplings=()):
        super().__init__(n, diag, weights, adj_start, adj, diag, inv_mass, couplings)
        self.mg = mg
        self.deflation = None
        self.deflated = False

    def deflate(self, deflation):
        """A second level (``deflation.PlaneDeflation`` of this solver), before the first
        solve: its pairs are deflated in every solve while its ``count`` is not 0."""
        self.deflation, self.deflated = deflation, True

    def _begin(self):
        """From x = 0, or from x = Q b where deflating."""
        if self.deflated and self.deflation.count:
            bb = self._deflated_guess()
            self._couple(self.x)
            self._deflated_residual()
            return bb
        return self._start()

    @ti.kernel
    def _deflated_guess(self) -> ti.f64:
        """x = Q b (``PlaneDeflation.guess``). Returns b.b over free particles."""
        bb = ti.cast(0.0, ti.f64)
        ti.loop_config(serialize=ti.static(serial(self.x)))
        for p in range(self.x.shape[0]):
            self.x[p] = ti.Vector.zero(float, 3)
            if self.inv_mass[p] > 0.0:
                bb += ti.cast(self.b[p].dot(self.b[p]), ti.f64)
        self.deflation.guess()
        return bb

    @ti.kernel
    def _deflated_residual(self):
        """r = b - A x (the couplings' part of A x in ``extra``), z = p = P^-1 r,
        scalars[0] = r.z."""
        ti.loop_config(serialize=ti.static(serial(self.x)))
        for p in range(self.x.shape[0]):
            rp = ti.Vector.zero(float, 3)
            if self.inv_mass[p] > 0.0:
                rp = self.b[p] - self._product(self.x, p)
            self.r[p] = rp
        self._first_direction()

    @ti.func
    def _precondition_r(self):
        """z = B r (a V-cycle), 0 on pinned particles, then z += Q (r - A z) where
        deflating (``PlaneDeflation.correct``); returns r.z."""
        ny, nx = ti.static(self.mg.shapes[0])
        ti.loop_config(serialize=ti.static(self.mg.serial))
        for j, i in ti.ndrange(ny, nx):
            self.mg.set_rhs(j, i, self.r[j * nx + i])
        self.mg.cycle()
        ti.loop_config(serialize=ti.static(self.mg.serial))
        for j, i in ti.ndrange(ny, nx):
            p = j * nx + i
            zp = ti.Vector.zero(float, 3)
            if self.inv_mass[p] > 0.0:
                zp = self.mg.result(j, i)
            self.z[p] = zp
        if ti.static(self.deflated):
            self.deflation.correct()
        rz = ti.cast(0.0, ti.f64)
        ti.loop_config(serialize=ti.static(serial(self.x)))
        for p in range(self.x.shape[0]):
            rz += ti.cast(self.r[p].dot(self.z[p]), ti.f64)
        return rz
