"""Backward Euler's Newton systems H dx = -grad E, assembled from the terms' 3 x 3 blocks
in Taichi kernels and solved by preconditioned conjugate gradients.

Two layouts, one interface (``assemble``, ``solve``, ``dx``, ``product``):
  - ``BlockHessian``: blocks per spring end, gathered per particle, with a block-Jacobi
    (3 x 3 per particle) preconditioner; any scene. The pair terms' couplings that the
    spring adjacency does not hold (self-contacts) enter CG's products matrix-free.
  - ``GridHessian``: for a scene that is one cloth grid and nothing else, the Hessian as
    block stencil weights on the grid, with a geometric multigrid V-cycle (Galerkin coarse
    levels built at each step's first Newton iteration, block Gauss-Seidel smoothing;
    ``block_multigrid.py``) as the preconditioner.
With ``exact`` the CG matrix carries the exact spring and membrane blocks (indefinite where
they are compressed) and the preconditioner the projected ones; else both the projected
ones.
Pinned particles' rows and columns are filtered out (Baraff & Witkin's filtered CG).
"""
import taichi as ti

from ..model import grid as grid_layout
from .. import runtime
from ..runtime import serial
from ..terms import springs as spring_term
from ..terms.springs import Springs
from . import block_multigrid, linalg


@ti.data_oriented
class BlockHessian:
    """H as per-particle diagonal blocks and per-adjacency-entry spring blocks."""

    def __init__(self, model, potential, exact):
        n, real = model.particle_count, runtime.real()
        self.potential, self.exact = potential, exact
        self.springs = potential.springs
        self.has_springs = self.springs is not None
        self.adj_start, self.adj = (self.springs or Springs(model)).adjacency()
        if self.springs is not None:
            self.pairs, self.rest = self.springs.pairs, self.springs.rest
            self.ks, self.kd = self.springs.ks, self.springs.kd
        self.inv_mass = model.inv_mass
        self.diag = ti.Vector.field(6, real, shape=n)
        self.precond = ti.Matrix.field(3, 3, real, shape=n)
        self.blocks = ti.Vector.field(6, real, shape=self.adj.shape[0])
        self.solver = linalg.PCG(n, self.diag, self.blocks, self.adj_start, self.adj,
                                 self.precond, model.inv_mass, potential.pair_terms)
        self.dx = self.solver.x

    def assemble(self, x, h, t, coarse=True):
        self.potential.prepare_blocks(x, h)
        self._assemble(x, h, t)

    def solve(self, grad, tol, max_iterations):
        """dx solving H dx = -grad on free particles. Returns (iterations, residual)."""
        linalg.scale_into(self.solver.b, -1.0, grad)
        return self.solver.solve(tol, max_iterations)

    def descent(self, grad):
        """dx = -P^-1 grad: the preconditioned gradient, P the projected (positive
        definite) blocks' block Jacobi; a descent direction of the Hessian's scale."""
        linalg.scale_into(self.solver.b, -1.0, grad)
        self.solver.precondition()

    def product(self, p):
        """H p for a field p (after ``assemble``), as (N,3) NumPy."""
        self.solver.apply(p, self.solver.ap)
        return self.solver.ap.to_numpy()

    @ti.kernel
    def _assemble(self, x: ti.template(), h: float, t: float):
        """Each spring's block (exact or projected) at both of its ends' adjacency
        entries, so that the CG products read them in order; the preconditioner from the
        projected blocks."""
        ti.loop_config(serialize=ti.static(serial(x)))
        for p in range(x.shape[0]):
            block = self.potential.particle_block(p, x, h, t)
            self.diag[p] = linalg.symmetric6(block)
            if ti.static(self.has_springs):
                d0 = ti.static(self.springs.d0)
                for k in range(self.adj_start[p], self.adj_start[p + 1]):
                    s, q = self.adj[k][0], self.adj[k][1]
                    exact, projected = spring_term.hessian_blocks(
                        x[p], x[q], self.ks[s], self.kd[s], self.rest[s], d0[s], h)
                    self.blocks[k] = linalg.symmetric6(exact if ti.static(self.exact)
                                                       else projected)
                    block += projected
            self.precond[p] = block.inverse()


@ti.data_oriented
class GridHessian:
    """H as block stencil weights on the model's single cloth grid, solved by CG
    preconditioned with a block multigrid V-cycle."""

    def __init__(self, model, potential, exact, grid):
        real = runtime.real()
        self.potential, self.exact, self.grid = potential, exact, grid
        self.grid_reals = model.grid_table.reals
        self.inv_mass = model.inv_mass
        self.mg = block_multigrid.BlockGridMultigrid(grid.nx, grid.ny,
                                                     grid_layout.stencil(grid.families))
        self.solver = block_multigrid.GridPCG(self.mg, own_matrix=exact)
        self.dx = ti.Vector.field(3, real, shape=model.particle_count)

    def assemble(self, x, h, t, coarse=True):
        """The fine blocks at x and the multigrid's levels; the coarse ones only when
        ``coarse`` (the first Newton iteration of a step), else kept from before."""
        self.potential.prepare_blocks(x, h)
        self._assemble(x, h, t)
        self.mg.build(coarse)

    def solve(self, grad, tol, max_iterations):
        self._rhs(grad)
        result = self.solver.solve(tol, max_iterations)
        self._solution()
        return result

    def descent(self, grad):
        """dx = -B grad: one V-cycle of the projected Hessian's multigrid on the gradient
        (symmetric positive definite), a descent direction of the Hessian's scale."""
        self._rhs(grad)
        self.solver.precondition()
        self._solution()

    def product(self, p):
        shape = self.mg.shapes[0] + (3,)
        return self.solver.product(p.to_numpy().reshape(shape)).reshape(-1, 3)

    @ti.kernel
    def _assemble(self, x: ti.template(), h: float, t: float):
        """At the centre each particle's own and spring blocks, at the other end of each
        spring it stores (``half_stencil``) minus its block; pinned particles' rows and
        columns 0. The multigrid gets the projected spring blocks, CG (``exact``) the
        exact ones."""
        ny, nx = ti.static(self.mg.shapes[0])
        stencil, half = ti.static(self.mg.stencil, self.mg.halves[0])
        x0 = ti.static(self.potential.x0)
        g = self.grid_reals[0]
        rest = grid_layout.rest_lengths(g)
        ti.loop_config(serialize=ti.static(self.mg.serial))
        for j, i in ti.ndrange(ny, nx):
            p = j * nx + i
            free = ti.cast(self.inv_mass[p] > 0.0, float)
            centre = self.potential.particle_block(p, x, h, t)
            centre_exact = centre
            for k in ti.static(range(1, len(stencil))):
                di, dj = ti.static(stencil[k])
                fam = ti.static(grid_layout.family_of(di, dj))
                stored = ti.static((di, dj) in half)
                coupling = ti.Matrix.zero(float, 3, 3)
                coupling_exact = ti.Matrix.zero(float, 3, 3)
                if 0 <= i + di < nx and 0 <= j + dj < ny:
                    q = (j + dj) * nx + i + di
                    ks, kd = grid_layout.stiffness(g, fam)
                    exact, projected = spring_term.hessian_blocks(
                        x[p], x[q], ks, kd, grid_layout.rest_length(rest, di, dj),
                        spring_term.direction(x0[p], x0[q]), h)
                    centre += projected
                    centre_exact += exact
                    if ti.static(stored):
                        if self.inv_mass[q] > 0.0:
                            coupling = -projected
                            coupling_exact = -exact
                if ti.static(stored):
                    k_half = ti.static(half.index((di, dj)))
                    self.mg.set_block(j, i, k_half, free * linalg.symmetric6(coupling))
                    if ti.static(self.exact):
                        self.solver.set_block(j, i, k_half,
                                              free * linalg.symmetric6(coupling_exact))
            self.mg.set_block(j, i, 0, free * linalg.symmetric6(centre))
            if ti.static(self.exact):
                self.solver.set_block(j, i, 0, free * linalg.symmetric6(centre_exact))

    @ti.kernel
    def _rhs(self, grad: ti.template()):
        """-grad E into the multigrid CG's right-hand side (0 at pinned particles)."""
        ny, nx = ti.static(self.mg.shapes[0])
        ti.loop_config(serialize=ti.static(self.mg.serial))
        for j, i in ti.ndrange(ny, nx):
            p = j * nx + i
            g = ti.Vector.zero(float, 3)
            if self.inv_mass[p] > 0.0:
                g = -grad[p]
            self.mg.set_rhs(j, i, g)

    @ti.kernel
    def _solution(self):
        ny, nx = ti.static(self.mg.shapes[0])
        ti.loop_config(serialize=ti.static(self.mg.serial))
        for j, i in ti.ndrange(ny, nx):
            self.dx[j * nx + i] = self.solver.x[j + block_multigrid.PAD,
                                                i + block_multigrid.PAD]


def make(model, potential, exact, grid):
    """The Hessian for the chosen layout: ``GridHessian`` on ``grid``, or block Jacobi."""
    if grid is not None:
        return GridHessian(model, potential, exact, grid)
    return BlockHessian(model, potential, exact)


__all__ = ["BlockHessian", "GridHessian", "make"]
