"""Block geometric multigrid for backward Euler's Newton Hessian (symmetric 3 x 3 blocks
per node and stencil offset) and the conjugate gradients it preconditions.

The fine blocks are written in a kernel (``set_block``); ``build`` forms the Galerkin
coarse levels from tables of fine-block terms (``galerkin.half_galerkin_terms``), the
diagonal blocks' inverses and the coarsest level's dense inverse. Block Gauss-Seidel
sweeps, forwards before and backwards after each coarse correction: no weight to
estimate, and convergent for any symmetric positive definite matrix. On one thread the
nodes go in order; in parallel in nine colours. The cycle is small kernels (they compile
faster than one large one): on one thread four for the fine level and two for the
coarse ones, in parallel a few per level.
"""
import numpy as np
import taichi as ti

from .. import runtime
from . import linalg
from .galerkin import PAD, WPAD, half_galerkin_terms, half_stencil
from .multigrid import GridLevels

__all__ = ["BlockGridMultigrid", "GridPCG", "PAD", "WPAD"]


@ti.data_oriented
class BlockGridMultigrid(GridLevels):
    """V-cycles for H e = r with H given by a symmetric 3x3 block per node and stencil
    offset, (xx, yy, zz, xy, xz, yz). H is symmetric, so each coupling is stored once
    (``half_stencil``: the centre and the offsets pointing forwards; the block of node p
    at offset -s is that of node p - s at s), in fields w[level][j + WPAD, i + WPAD, k]
    padded by zeros. The caller writes the fine blocks (``set_block``, in its own kernel)
    and calls ``build``, which forms the coarse levels (``galerkin_terms``), the diagonal
    blocks' inverses and the coarsest inverse. Symmetric block Gauss-Seidel smoothing: in
    node order on one thread; in parallel, nodes coloured (j mod 3, i mod 3) couple with
    no node of their colour (stencils reach 2), so each colour updates at once."""

    def __init__(self, nx, ny, stencil):
        super().__init__(nx, ny, stencil)
        real = runtime.real()
        self.halves = [half_stencil(s) for s in self.stencils]
        self.w = [ti.Vector.field(6, real, shape=(sy + 2 * WPAD, sx + 2 * WPAD, len(h)))
                  for h, (sy, sx) in zip(self.halves, self.shapes)]
        self.inv_diag = [ti.Matrix.field(3, 3, real, shape=shape) for shape in self.shapes]
        # the coarse levels' stored blocks as sums of stored fine blocks, in tables: terms
        # start[s] .. start[s + 1] of stored offset s are (dj, di, k) and c
        self.term_start, self.term_index, self.term_weight = [], [], []
        for stencil in self.stencils[:-1]:
            terms = half_galerkin_terms(stencil)
            flat = [t for slot in terms for t in slot]
            start = ti.field(ti.i32, shape=len(terms) + 1)
            start.from_numpy(np.cumsum([0] + [len(t) for t in terms]).astype(np.int32))
            index = ti.Vector.field(3, ti.i32, shape=len(flat))
            index.from_numpy(np.array([t[:3] for t in flat], dtype=np.int32))
            weight = ti.field(real, shape=len(flat))
            weight.from_numpy(np.array([t[3] for t in flat], dtype=runtime.numpy_real()))
            self.term_start.append(start)
            self.term_index.append(index)
            self.term_weight.append(weight)
        self.offsets = []
        for half in self.halves:
            offsets = ti.Vector.field(2, ti.i32, shape=len(half))
            offsets.from_numpy(np.array(half, dtype=np.int32))
            self.offsets.append(offsets)

    @ti.func
    def set_block(self, j, i, k, block):
        """The fine matrix's block (``linalg.symmetric6``) at node (j, i), offset
        ``halves[0][k]``."""
        self.w[0][j + WPAD, i + WPAD, k] = block

    def stored_blocks(self, weights):
        """Fine blocks (ny, nx, len(stencil), 6) over the whole stencil in the layout of
        ``w[0]``: the ``half_stencil``'s blocks, padded (for tests and tools)."""
        half = weights[:, :, [self.stencil.index(o) for o in self.halves[0]]]
        return np.pad(half, ((WPAD, WPAD), (WPAD, WPAD), (0, 0), (0, 0))).astype(
            runtime.numpy_real())

    def set_matrix(self, weights):
        """Fine blocks from NumPy (ny, nx, len(stencil), 6) over the whole stencil, then
        ``build`` (for tests and tools)."""
        self.w[0].from_numpy(self.stored_blocks(weights))
        self.build()

    def level_weights(self, level):
        """Level ``level``'s blocks over its whole stencil, (ny, nx, len(stencil), 6)."""
        padded = self.w[level].to_numpy()
        ny, nx = self.shapes[level]
        half = self.halves[level]
        out = []
        for di, dj in self.stencils[level]:
            if (di, dj) in half:
                out.append(padded[WPAD:WPAD + ny, WPAD:WPAD + nx, half.index((di, dj))])
            else:
                out.append(padded[WPAD + dj:WPAD + dj + ny, WPAD + di:WPAD + di + nx,
                                  half.index((-di, -dj))])
        return np.stack(out, axis=2)

    def build(self, coarse=True):
        """The levels from the fine blocks; coarse=False updates only the fine level's
        smoother and keeps the coarse levels of an earlier matrix: the cycle stays a
        symmetric positive definite preconditioner (its coarse correction need only be
        positive definite), somewhat weaker."""
        self._invert_diagonal(0)
        if coarse:
            self._coarsen()

    @ti.kernel
    def _coarsen(self):
        """Each coarse level's blocks (Galerkin, from the next finer level) and inverse
        diagonal; the coarsest level's inverse."""
        for level in ti.static(range(1, self.levels)):
            ny, nx = ti.static(self.shapes[level])
            fine = ti.static(self.w[level - 1])
            start, index, weight = ti.static(self.term_start[level - 1],
                                             self.term_index[level - 1],
                                             self.term_weight[level - 1])
            ti.loop_config(serialize=ti.static(self.serial))
            for J, I in ti.ndrange(ny, nx):
                for s in range(ti.static(len(self.halves[level]))):
                    acc = ti.Vector.zero(float, 6)
                    for t in range(start[s], start[s + 1]):
                        dj, di, k = index[t][0], index[t][1], index[t][2]
                        acc += weight[t] * fine[2 * J + WPAD + dj, 2 * I + WPAD + di, k]
                    self.w[level][J + WPAD, I + WPAD, s] = acc
            self._inverse_loop(level)
        self._coarsest_matrix()
        self._invert_coarsest()

    @ti.func
    def _coarsest_matrix(self):
        """The coarsest level's blocks as its dense matrix, in ``coarsest_inverse``."""
        last = ti.static(self.levels - 1)
        ny, nx = ti.static(self.shapes[last])
        a, w, offsets = ti.static(self.coarsest_inverse, self.w[last], self.offsets[last])
        ti.loop_config(serialize=True)
        for r, c in ti.ndrange(a.shape[0], a.shape[1]):
            a[r, c] = 0.0
        ti.loop_config(serialize=True)
        for j, i in ti.ndrange(ny, nx):
            for k in range(offsets.shape[0]):
                di, dj = offsets[k][0], offsets[k][1]
                if 0 <= i + di < nx and 0 <= j + dj < ny:
                    block = linalg.unpack6(w[j + WPAD, i + WPAD, k])
                    p, q = 3 * (j * nx + i), 3 * ((j + dj) * nx + i + di)
                    for u in ti.static(range(3)):
                        for v in ti.static(range(3)):
                            a[p + u, q + v] = block[u, v]
                            a[q + v, p + u] = block[u, v]

    @ti.kernel
    def _invert_diagonal(self, level: ti.template()):
        self._inverse_loop(level)

    @ti.func
    def _inverse_loop(self, level: ti.template()):
        """The inverses of the level's diagonal blocks (0 at inactive nodes)."""
        ny, nx = ti.static(self.shapes[level])
        ti.loop_config(serialize=ti.static(self.serial))
        for j, i in ti.ndrange(ny, nx):
            d = linalg.unpack6(self.w[level][j + WPAD, i + WPAD, 0])
            inv = ti.Matrix.zero(float, 3, 3)
            if d.trace() > 0.0:
                inv = d.inverse()
            self.inv_diag[level][j, i] = inv

    def _solution(self, level):
        return self.t[level] if level == self.levels - 1 else self.e[level]

    @ti.func
    def _active(self, level: ti.template(), j, i):
        return self.inv_diag[level][j, i][0, 0] > 0.0

    @ti.func
    def product_at(self, level: ti.template(), v: ti.template(), j, i):
        """(H_level v) at node (j, i) (unpadded indices) of a padded field v."""
        return self.product_with(self.w[level], level, v, j, i)

    @ti.func
    def product_with(self, w: ti.template(), level: ti.template(), v: ti.template(), j, i):
        """(W v) at node (j, i) for blocks w laid out like level ``level``'s: the centre,
        and each stored offset s both ways (node + s with this node's block, node - s with
        that node's). The fine level's stencil is unrolled; coarse levels loop over theirs
        (a quarter of the work or less per level, and a much shorter compile)."""
        acc = linalg.symmetric6_times(w[j + WPAD, i + WPAD, 0], v[j + PAD, i + PAD])
        if ti.static(level == 0):
            for k in ti.static(range(1, len(self.halves[0]))):
                di, dj = ti.static(self.halves[0][k])
                acc += self._coupling(w, v, j, i, k, di, dj)
        else:
            offsets = ti.static(self.offsets[level])
            for k in range(1, offsets.shape[0]):
                acc += self._coupling(w, v, j, i, k, offsets[k][0], offsets[k][1])
        return acc

    @ti.func
    def _coupling(self, w: ti.template(), v: ti.template(), j, i, k, di, dj):
        """Stored offset k = (di, dj) of node (j, i) both ways: node + (di, dj) through this
        node's block, node - (di, dj) through that node's."""
        jw, iw = j + WPAD, i + WPAD
        return (linalg.symmetric6_times(w[jw, iw, k], v[j + PAD + dj, i + PAD + di])
                + linalg.symmetric6_times(w[jw - dj, iw - di, k], v[j + PAD - dj, i + PAD - di]))

    @ti.func
    def _begin_level(self, level: ti.template(), j, i, r):
        self.e[level][j + PAD, i + PAD] = ti.Vector.zero(float, 3)

    @ti.func
    def set_rhs(self, j, i, rhs):
        """The finest level's right-hand side at node (j, i) (0 at inactive nodes)."""
        self.r[0][j + PAD, i + PAD] = rhs
        self._begin_level(0, j, i, rhs)

    def cycle(self):
        """A V-cycle after ``set_rhs`` at every fine node; the correction ends in
        ``result``. Launched as small kernels: Taichi's compile time grows faster than the
        number of loops in a kernel. A serial grid runs its coarse levels in two launches,
        down and up, which compile faster than one (docs/implicit.md)."""
        if self.levels == 1:
            self._coarsest()
            return
        self._smooth(0, False)
        self._residual_restrict(0)
        if self.serial:
            self._coarse_down()
            self._coarse_up()
        else:
            for level in range(1, self.levels - 1):
                self._smooth(level, False)
                self._residual_restrict(level)
            self._coarsest()
            for level in range(self.levels - 2, 0, -1):
                self._prolong_kernel(level)
                self._smooth(level, True)
        self._prolong_kernel(0)
        self._smooth(0, True)

    _run_cycle = cycle

    def _smooth(self, level, backward):
        """One block Gauss-Seidel sweep on e_l: forwards, or backwards (the adjoint
        sweep, so that the cycle is symmetric). A serial grid sweeps its nodes in
        order (``_serial_sweep``); a parallel one colour by colour, a kernel per colour."""
        if self.serial:
            self._serial_sweep(level, backward)
        else:
            for c in range(8, -1, -1) if backward else range(9):
                self._parallel_colour(level, c // 3, c % 3)

    @ti.kernel
    def _serial_sweep(self, level: ti.template(), backward: ti.template()):
        self._sweep_in_order(level, backward)

    @ti.func
    def _sweep_in_order(self, level: ti.template(), backward: ti.template()):
        """Lexicographic Gauss-Seidel on one thread: each node relaxes with its
        predecessors' new values. It reads w in memory order, where the colours read it
        nine times with a stride, and smooths at least as well (docs/implicit.md)."""
        ny, nx = ti.static(self.shapes[level])
        ti.loop_config(serialize=True)
        for n in range(ny * nx):
            m = ny * nx - 1 - n if ti.static(backward) else n
            self._relax(level, m // nx, m % nx)

    @ti.kernel
    def _coarse_down(self):
        """Levels 1 and coarser of a serial V-cycle on the way down, after
        ``_residual_restrict(0)``, and the coarsest solve."""
        for level in ti.static(range(1, self.levels - 1)):
            self._sweep_in_order(level, False)
            self._residual_restrict_loops(level)
        self._solve_coarsest()

    @ti.kernel
    def _coarse_up(self):
        """Levels coarser than 0 of a serial V-cycle on the way up."""
        for level in ti.static(range(self.levels - 2, 0, -1)):
            self._prolong(level)
            self._sweep_in_order(level, True)

    @ti.kernel
    def _parallel_colour(self, level: ti.template(), cj: ti.i32, ci: ti.i32):
        ny, nx = ti.static(self.shapes[level])
        for J, I in ti.ndrange((ny - cj + 2) // 3, (nx - ci + 2) // 3):
            self._relax(level, 3 * J + cj, 3 * I + ci)

    @ti.kernel
    def _residual_restrict(self, level: ti.template()):
        self._residual_restrict_loops(level)

    @ti.func
    def _residual_restrict_loops(self, level: ti.template()):
        """The residual of the pre-smoothed solution, restricted to the next level."""
        ny, nx = ti.static(self.shapes[level])
        ti.loop_config(serialize=ti.static(self.serial))
        for j, i in ti.ndrange(ny, nx):
            self.t[level][j + PAD, i + PAD] = (self.r[level][j + PAD, i + PAD]
                                               - self.product_at(level, self.e[level], j, i))
        self._restrict(level)

    @ti.kernel
    def _coarsest(self):
        self._solve_coarsest()

    @ti.kernel
    def _prolong_kernel(self, level: ti.template()):
        self._prolong(level)

    @ti.func
    def _relax(self, level: ti.template(), j, i):
        """e_l at node (j, i) solves its own rows of H_l e_l = r_l; nodes of one colour
        (j mod 3, i mod 3) never couple (stencils reach 2), so they relax in parallel."""
        res = self.r[level][j + PAD, i + PAD] - self.product_at(level, self.e[level], j, i)
        self.e[level][j + PAD, i + PAD] += self.inv_diag[level][j, i] @ res

    @ti.kernel
    def _apply(self, w: ti.template()):
        ny, nx = ti.static(self.shapes[0])
        for j, i in ti.ndrange(ny, nx):
            self.t[0][j + PAD, i + PAD] = self.product_with(w, 0, self.e[0], j, i)

    def product(self, v, w=None):
        """H v (or W v for fine blocks w) for a (ny, nx, 3) NumPy array (for tests and
        tools)."""
        self.e[0].from_numpy(np.pad(v, ((PAD, PAD), (PAD, PAD), (0, 0)))
                             .astype(runtime.numpy_real()))
        self._apply(self.w[0] if w is None else w)
        return self.t[0].to_numpy()[PAD:-PAD, PAD:-PAD]


@ti.data_oriented
class GridPCG(linalg.ConjugateGradients):
    """Conjugate gradients on H x = b on the grid, preconditioned by one V-cycle of
    ``BlockGridMultigrid`` ``mg`` (Galerkin coarse levels: a few iterations whatever the
    grid size). H is the cycle's own fine matrix, or with ``own_matrix`` another one of
    the same layout written with ``set_block`` (the cycle then preconditions a matrix
    other than the one it inverts). The right-hand side goes in with ``mg.set_rhs`` in a
    kernel, or ``mg.load_rhs`` from NumPy (0 at inactive nodes, which stay 0); the
    solution is ``x`` (padded like the cycle's fields).
    An iteration is the cycle's launches and one more; the residual is the cycle's own
    right-hand side field."""

    def __init__(self, mg, own_matrix=False):
        self.mg = mg
        real = runtime.real()
        ny, nx = mg.shapes[0]
        self.w = (ti.Vector.field(6, real, shape=mg.w[0].shape) if own_matrix
                  else mg.w[0])
        self.x, self.p, self.ap = (ti.Vector.field(3, real, shape=(ny + 2 * PAD, nx + 2 * PAD))
                                   for _ in range(3))
        self.scalars = ti.field(ti.f64, shape=3)     # r.z, p.Ap, the next r.z

    @ti.kernel
    def _start(self) -> ti.f64:
        """x = p = 0; returns r.r."""
        ny, nx = ti.static(self.mg.shapes[0])
        self.scalars[0] = 0.0
        rr = ti.cast(0.0, ti.f64)
        ti.loop_config(serialize=ti.static(self.mg.serial))
        for j, i in ti.ndrange(ny, nx):
            self.x[j + PAD, i + PAD] = ti.Vector.zero(float, 3)
            self.p[j + PAD, i + PAD] = ti.Vector.zero(float, 3)
            r = self.mg.r[0][j + PAD, i + PAD]
            rr += ti.cast(r.dot(r), ti.f64)
        return rr

    @ti.func
    def set_block(self, j, i, k, block):
        """H's block at node (j, i), offset ``mg.halves[0][k]`` (``own_matrix``)."""
        self.w[j + WPAD, i + WPAD, k] = block

    def product(self, v):
        """H v for a (ny, nx, 3) NumPy array (for tests and tools)."""
        return self.mg.product(v, self.w)

    def _iterate(self):
        """z = B r (``mg.cycle``), then one CG iteration (``_update``)."""
        self.mg.cycle()
        return self._update()

    def precondition(self):
        """x = B b: one V-cycle on the right-hand side."""
        self._start()
        self.mg.cycle()
        self._take_cycle()

    @ti.kernel
    def _take_cycle(self):
        ny, nx = ti.static(self.mg.shapes[0])
        ti.loop_config(serialize=ti.static(self.mg.serial))
        for j, i in ti.ndrange(ny, nx):
            self.x[j + PAD, i + PAD] = self.mg.result(j, i)

    @ti.kernel
    def _update(self) -> ti.f64:
        """With z = B r: beta = r.z / (the last r.z) (0 at the first iteration);
        p = z + beta p; alpha = r.z / p.Hp; x += alpha p; r -= alpha Hp. Returns r.r, or -1
        when p.Hp <= 0 (x and r are then left unchanged)."""
        ny, nx = ti.static(self.mg.shapes[0])
        r = ti.static(self.mg.r[0])
        self.scalars[1] = 0.0
        self.scalars[2] = 0.0
        ti.loop_config(serialize=ti.static(self.mg.serial))
        for j, i in ti.ndrange(ny, nx):
            self.scalars[2] += ti.cast(r[j + PAD, i + PAD].dot(self.mg.result(j, i)), ti.f64)
        ti.loop_config(serialize=ti.static(self.mg.serial))
        for j, i in ti.ndrange(ny, nx):
            beta = 0.0
            if self.scalars[0] > 0.0:
                beta = ti.cast(self.scalars[2] / self.scalars[0], float)
            self.p[j + PAD, i + PAD] = self.mg.result(j, i) + beta * self.p[j + PAD, i + PAD]
        ti.loop_config(serialize=ti.static(self.mg.serial))
        for j, i in ti.ndrange(ny, nx):
            ap = self.mg.product_with(self.w, 0, self.p, j, i)
            self.ap[j + PAD, i + PAD] = ap
            self.scalars[1] += ti.cast(self.p[j + PAD, i + PAD].dot(ap), ti.f64)
        rr = ti.cast(0.0, ti.f64)
        ti.loop_config(serialize=ti.static(self.mg.serial))
        for j, i in ti.ndrange(ny, nx):
            if self.scalars[1] > 0.0:
                alpha = ti.cast(self.scalars[2] / self.scalars[1], float)
                self.x[j + PAD, i + PAD] += alpha * self.p[j + PAD, i + PAD]
                rn = r[j + PAD, i + PAD] - alpha * self.ap[j + PAD, i + PAD]
                self.mg.set_rhs(j, i, rn)
                rr += ti.cast(rn.dot(rn), ti.f64)
        if self.scalars[1] <= 0.0:
            rr = -1.0
        self.scalars[0] = self.scalars[2]
        return rr
