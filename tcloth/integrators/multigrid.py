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
    (scalar weights), built once per scene in NumPy. One weighted Jacobi sweep before and
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
(they compile far faster): on one thread four for the fine level and two for the coarse
ones, in parallel a few per level. ``vcycle`` runs one from NumPy for tests and tools.
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..errors import SceneError
from ..forces import OWNED
from . import linalg

PAD = 2
WPAD = 3          # the block weights' padding: Galerkin sums reach 3 past a coarse node
COARSEST_NODES = 64


def grid_stencil(families):
    """The offsets (di, dj) a Provot grid's matrix couples: itself and both ends of each
    owned spring of the families present."""
    stencil = [(0, 0)]
    for fam, present in enumerate(families):
        if present:
            for di, dj in OWNED[fam]:
                stencil += [(di, dj), (-di, -dj)]
    return tuple(stencil)


def single_grid(model, linear_solver):
    """The cloth grid a multigrid solves on, for the option ``linear_solver``: "auto"
    (the grid when it is the whole scene, else None), "multigrid" (that grid, or
    SceneError) or "cg" (None)."""
    if linear_solver not in ("auto", "multigrid", "cg"):
        raise SceneError("linear_solver must be 'auto', 'multigrid' or 'cg' "
                         f"(got {linear_solver!r})")
    grid = None
    if len(model.grids) == 1 and model.list_spring_count == 0:
        g = model.grids[0]
        if g.offset == 0 and g.nx * g.ny == model.particle_count:
            grid = g
    if linear_solver == "multigrid" and grid is None:
        raise SceneError("linear_solver='multigrid' needs a scene that is one cloth grid "
                         "and nothing else (no other particles or springs)")
    return grid if linear_solver in ("auto", "multigrid") else None


def coarse_size(n):
    """Coarse nodes for n fine ones: 2I covers 0 .. n - 1, and one node past an even n."""
    return n // 2 + 1


def prolongation_1d(n_fine):
    """(n_fine, coarse_size(n_fine)) bilinear: fine 2I takes coarse I, an odd node the mean
    of its two coarse neighbours."""
    p = np.zeros((n_fine, coarse_size(n_fine)))
    for f in range(n_fine):
        p[f, f // 2] = 1.0 if f % 2 == 0 else 0.5
        if f % 2:
            p[f, f // 2 + 1] = 0.5
    return p


def apply_stencil(weights, stencil, v):
    """sum_k weights[..., k] v[j + dj_k, i + di_k] on a (ny, nx) grid, zero outside."""
    ny, nx = v.shape
    padded = np.pad(v, PAD)
    out = np.zeros_like(v)
    for k, (di, dj) in enumerate(stencil):
        out += weights[..., k] * padded[PAD + dj:PAD + dj + ny, PAD + di:PAD + di + nx]
    return out


def coarse_stencil(stencil):
    """The offsets P^T A P can couple when A couples ``stencil``: coarse nodes I, K meet
    where fine nodes 2I + u, 2K + w (|u|, |w| <= 1 per axis) are a stencil offset apart,
    so 2 (K - I) = s + (u - w). Within 5 x 5 while the stencil reaches at most 2; the
    Provot stencil and its coarse ones give 21 (no corners: no offset reaches 2 on both
    axes)."""
    offsets = {(di, dj) for si, sj in stencil for di in range(-2, 3) for dj in range(-2, 3)
               if abs(2 * di - si) <= 2 and abs(2 * dj - sj) <= 2}
    return tuple(sorted(offsets, key=lambda o: (o[1], o[0])))


def galerkin_terms(stencil):
    """P^T A P at coarse node (J, I) as sums of fine weights: for each offset of
    ``coarse_stencil(stencil)`` the terms (dj, di, k, c), c times weight k of fine node
    (2J + dj, 2I + di). The fine nodes are the nine P maps node (J, I) to (|di|, |dj| <= 1,
    weight (1 - |di|/2) (1 - |dj|/2)); weight k couples one to fine node b, which P^T maps
    to the coarse node(s) next to it: b/2 when b is even, else both halves at 1/2 (per axis,
    relative to 2J, 2I)."""
    coarse = coarse_stencil(stencil)
    slot = {offset: n for n, offset in enumerate(coarse)}
    terms = [[] for _ in coarse]

    def parents(b):
        return [(b // 2, 1.0)] if b % 2 == 0 else [((b - 1) // 2, 0.5), ((b + 1) // 2, 0.5)]
    for dj in (-1, 0, 1):
        for di in (-1, 0, 1):
            weight = (1.0 - abs(di) / 2) * (1.0 - abs(dj) / 2)
            for k, (si, sj) in enumerate(stencil):
                for ci, wi in parents(di + si):
                    for cj, wj in parents(dj + sj):
                        terms[slot[(ci, cj)]].append((dj, di, k, weight * wi * wj))
    return tuple(tuple(t) for t in terms)


def half_stencil(stencil):
    """The centre and the offsets of a symmetric stencil that point forwards (dj > 0, or
    dj = 0 and di > 0): each coupling once."""
    return ((0, 0),) + tuple(o for o in stencil if o[1] > 0 or (o[1] == 0 and o[0] > 0))


def half_galerkin_terms(stencil):
    """``galerkin_terms`` for blocks stored over ``half_stencil``s: the terms of the coarse
    half's offsets, each reading a stored fine block (a block at offset -s of fine node a
    is the one at offset s of node a - s)."""
    coarse, half = coarse_stencil(stencil), half_stencil(stencil)
    full = galerkin_terms(stencil)
    out = []
    for offset in half_stencil(coarse):
        terms = []
        for dj, di, k, c in full[coarse.index(offset)]:
            si, sj = stencil[k]
            if (si, sj) in half:
                terms.append((dj, di, half.index((si, sj)), c))
            else:
                terms.append((dj + sj, di + si, half.index((-si, -sj)), c))
        out.append(tuple(terms))
    return tuple(out)


def galerkin(weights, stencil):
    """P^T A P as (nyc, nxc, len(coarse_stencil(stencil)), ...) weights, from fine weights
    (ny, nx, len(stencil), ...): scalars, or blocks in a trailing axis."""
    ny, nx = weights.shape[:2]
    cy, cx = coarse_size(ny), coarse_size(nx)
    padded = np.pad(weights, [(PAD, PAD), (PAD, PAD)] + [(0, 0)] * (weights.ndim - 2))
    terms = galerkin_terms(stencil)
    out = np.zeros((cy, cx, len(terms)) + weights.shape[3:])
    for s, slot_terms in enumerate(terms):
        for dj, di, k, c in slot_terms:
            out[:, :, s] += c * padded[PAD + dj:PAD + dj + 2 * cy:2,
                                       PAD + di:PAD + di + 2 * cx:2, k]
    return out


def symmetric_blocks(w6):
    """(..., 6) symmetric 3x3 blocks (xx, yy, zz, xy, xz, yz) as (..., 3, 3)."""
    xx, yy, zz, xy, xz, yz = np.moveaxis(w6, -1, 0)
    return np.stack([np.stack([xx, xy, xz], -1), np.stack([xy, yy, yz], -1),
                     np.stack([xz, yz, zz], -1)], -2)


def dense_matrix(weights, stencil):
    """The matrix of a stencil operator on a (ny, nx) grid, rows j * nx + i: (n, n) from
    scalar weights (ny, nx, k), (3n, 3n) from symmetric blocks (ny, nx, k, 6) (rows
    3 (j * nx + i) + component)."""
    ny, nx = weights.shape[:2]
    blocks = symmetric_blocks(weights) if weights.ndim == 4 else weights[..., None, None]
    b = blocks.shape[-1]
    n = ny * nx
    a = np.zeros((n, n, b, b))
    jj, ii = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    for k, (di, dj) in enumerate(stencil):
        inside = (0 <= jj + dj) & (jj + dj < ny) & (0 <= ii + di) & (ii + di < nx)
        rows = (jj * nx + ii)[inside]
        a[rows, rows + dj * nx + di] += blocks[inside, k]
    return a.transpose(0, 2, 1, 3).reshape(n * b, n * b)


def smoothing_weight(weights, stencil, iterations=30):
    """The Jacobi weight 4 / (3 lambda), lambda the largest eigenvalue of D^-1 A by power
    iteration (rows with a zero diagonal are inactive), raised by 5 % against an
    underestimate."""
    diag = weights[..., stencil.index((0, 0))]
    inv = np.where(diag > 0, 1.0 / np.where(diag > 0, diag, 1.0), 0.0)
    v = np.random.default_rng(0).uniform(-1.0, 1.0, diag.shape) * (diag > 0)
    lam = 1.0
    for _ in range(iterations):
        w = inv * apply_stencil(weights, stencil, v)
        lam = np.abs(w).max() / max(np.abs(v).max(), 1e-300)
        v = w / max(np.abs(w).max(), 1e-300)
    return 4.0 / (3.0 * 1.05 * lam)


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
    smoothing."""

    def __init__(self, nx, ny, stencil):
        super().__init__(nx, ny, stencil)
        real = runtime.real()
        self.w = [ti.Vector.field(len(s), real, shape=shape)
                  for s, shape in zip(self.stencils, self.shapes)]
        self.inv_diag = [ti.field(real, shape=shape) for shape in self.shapes]
        self.omega = ti.field(real, shape=len(self.shapes))

    def set_matrix(self, weights):
        """Fine stencil weights (ny, nx, len(stencil)); builds every level."""
        npr = runtime.numpy_real()
        omegas = []
        for level, stencil in enumerate(self.stencils):
            diag = weights[..., stencil.index((0, 0))]
            self.w[level].from_numpy(weights.astype(npr))
            self.inv_diag[level].from_numpy(
                np.where(diag > 0, 1.0 / np.where(diag > 0, diag, 1.0), 0.0).astype(npr))
            omegas.append(smoothing_weight(weights, stencil))
            if level + 1 < self.levels:
                weights = galerkin(weights, stencil)
        self.omega.from_numpy(np.array(omegas, dtype=npr))
        self._set_coarsest(np.kron(dense_matrix(weights, self.stencils[-1]), np.eye(3)))

    def _solution(self, level):
        return self.t[level]

    @ti.func
    def _active(self, level: ti.template(), j, i):
        return self.inv_diag[level][j, i] > 0.0

    @ti.func
    def product_at(self, level: ti.template(), v: ti.template(), j, i):
        """(A_level v) at node (j, i) (unpadded indices) of a padded field v."""
        acc = ti.Vector.zero(float, 3)
        w = self.w[level][j, i]
        for k in ti.static(range(len(self.stencils[level]))):
            di, dj = ti.static(self.stencils[level][k])
            acc += w[k] * v[j + PAD + dj, i + PAD + di]
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
        number of loops in a kernel (the whole cycle as one kernel, with a loop per colour,
        took minutes to compile on a 13 x 18 grid). A serial grid runs its coarse levels
        in two launches, down and up (each launch costs about 50 us of Python; on
        128 x 128 the two compile in 5.9 s, one kernel for both took 8.2 s)."""
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
        nine times with a stride, and smooths at least as well. On the 128 x 128
        benchmark cloth, side by side: a fine sweep 1.0-1.2 ms against 1.2-1.6 ms; the
        single linearised solve 3 CG iterations a step (median over the swing) against
        4."""
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
