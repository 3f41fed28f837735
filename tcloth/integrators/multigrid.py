"""Geometric multigrid for a constant, scalar, symmetric matrix on one cloth grid.

The projective solver's matrix A = M/h^2 + c/h + sum_s w_s A_s A_s^T couples each grid
particle with the ends of its springs: on a Provot grid, a stencil of 13 points (itself,
4 structural, 4 shear, 4 flexion neighbours). Here it is stored per node as stencil
weights, with pinned particles filtered out (their rows and columns are 0, so they never
move). Coarser levels halve the grid in both directions (nodes 2I of the finer level)
with bilinear prolongation P (an even-sized grid gets a coarse node one past its end)
and Galerkin operators A_c = P^T A P, which stay within a 5 x 5 stencil (21 points for
Provot cloth); they are found once per matrix by probing: P^T A P applied to 25 comb
vectors, each hitting every coarse node's stencil at one offset. The coarsest level
(64 nodes or fewer) is solved exactly with its dense inverse.

One V-cycle (one weighted Jacobi sweep before and one after each coarse correction,
weight 4/3 over the largest eigenvalue of D^-1 A) is a symmetric positive-definite
approximation B of A^-1 with the spectrum of B A in (0, 1]. Vectors are vec3 (the matrix
is the same for x, y and z) in fields padded by two nodes of zeros on every side, so
that stencils need no bounds tests. The cycle's loops are ``ti.func`` bodies meant to be
called from a kernel, so that a whole cycle is one launch; ``vcycle`` runs one from
NumPy for tests and tools.
"""
import numpy as np
import taichi as ti

from .. import runtime

PAD = 2
COARSEST_NODES = 64


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


def galerkin(weights, stencil, py, px):
    """P^T A P, P = py (x) px, as (nyc, nxc, k) weights over coarse_stencil(stencil):
    probed with 25 combs of coarse nodes 5 apart, each node's stencil met once per comb."""
    nyc, nxc = py.shape[1], px.shape[1]
    full = np.zeros((nyc, nxc, 5, 5))
    jj, ii = np.meshgrid(np.arange(nyc), np.arange(nxc), indexing="ij")
    for cj in range(5):
        for ci in range(5):
            comb = np.zeros((nyc, nxc))
            comb[cj::5, ci::5] = 1.0
            column = py.T @ apply_stencil(weights, stencil, py @ comb @ px.T) @ px
            # the comb node within two of (J, I) is at (cj - J) mod 5 - 2 ... + 2
            dj = (cj - jj + 2) % 5 - 2
            di = (ci - ii + 2) % 5 - 2
            full[jj, ii, dj + 2, di + 2] = column
    offsets = coarse_stencil(stencil)
    out = np.zeros((nyc, nxc, len(offsets)))
    for k, (di, dj) in enumerate(offsets):
        inside = (0 <= jj + dj) & (jj + dj < nyc) & (0 <= ii + di) & (ii + di < nxc)
        out[..., k] = np.where(inside, full[..., dj + 2, di + 2], 0.0)
    return out


def dense_matrix(weights, stencil):
    """The (n, n) matrix of a stencil operator on a (ny, nx) grid, rows j * nx + i."""
    ny, nx = weights.shape[:2]
    a = np.zeros((ny * nx, ny * nx))
    for j in range(ny):
        for i in range(nx):
            for k, (di, dj) in enumerate(stencil):
                if 0 <= j + dj < ny and 0 <= i + di < nx and weights[j, i, k] != 0.0:
                    a[j * nx + i, (j + dj) * nx + i + di] += weights[j, i, k]
    return a


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
class GridMultigrid:
    """V-cycles for A e = r on an (ny, nx) grid; A given by ``set_matrix`` as fine stencil
    weights (ny, nx, len(stencil)) over ``stencil``, a tuple of (di, dj) offsets."""

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
        # smoothed solution on the way up (the level's result)
        self.e, self.r, self.t = padded(), padded(), padded()
        self.w = [ti.Vector.field(len(s), real, shape=shape)
                  for s, shape in zip(self.stencils, self.shapes)]
        self.inv_diag = [ti.field(real, shape=shape) for shape in self.shapes]
        self.omega = ti.field(real, shape=len(self.shapes))
        nc = self.shapes[-1][0] * self.shapes[-1][1]
        self.coarsest_inverse = ti.field(real, shape=(nc, nc))
        self.prolongations = [(prolongation_1d(fy), prolongation_1d(fx))
                              for fy, fx in self.shapes[:-1]]

    @property
    def levels(self):
        return len(self.shapes)

    def set_matrix(self, weights):
        """Fine stencil weights (ny, nx, len(stencil)); builds every level."""
        npr = runtime.numpy_real()
        omegas = []
        for level, stencil in enumerate(self.stencils):
            centre = stencil.index((0, 0))
            diag = weights[..., centre]
            self.w[level].from_numpy(weights.astype(npr))
            self.inv_diag[level].from_numpy(
                np.where(diag > 0, 1.0 / np.where(diag > 0, diag, 1.0), 0.0).astype(npr))
            omegas.append(smoothing_weight(weights, stencil))
            if level + 1 < self.levels:
                py, px = self.prolongations[level]
                weights = galerkin(weights, stencil, py, px)
        self.omega.from_numpy(np.array(omegas, dtype=npr))
        dense = dense_matrix(weights, self.stencils[-1])
        active = np.diag(dense) > 0
        inverse = np.zeros_like(dense)
        inverse[np.ix_(active, active)] = np.linalg.inv(dense[np.ix_(active, active)])
        self.coarsest_inverse.from_numpy(inverse.astype(npr))

    # -- the cycle's pieces (ti.func: called from kernels) ----------------------------------
    @ti.func
    def _product(self, level: ti.template(), v: ti.template(), j, i):
        """(A_level v) at node (j, i) (unpadded indices) of a padded field v."""
        acc = ti.Vector.zero(float, 3)
        w = self.w[level][j, i]
        for k in ti.static(range(len(self.stencils[level]))):
            di, dj = ti.static(self.stencils[level][k])
            acc += w[k] * v[j + PAD + dj, i + PAD + di]
        return acc

    @ti.func
    def set_rhs(self, j, i, rhs):
        """The finest level's right-hand side at node (j, i), and its first Jacobi sweep
        from 0."""
        self.r[0][j + PAD, i + PAD] = rhs
        self.e[0][j + PAD, i + PAD] = self.omega[0] * self.inv_diag[0][j, i] * rhs

    @ti.func
    def result(self, j, i):
        """The cycle's correction at fine node (j, i)."""
        return self.t[0][j + PAD, i + PAD]

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
                                                   - self._product(level, self.e[level], j, i))
            self._restrict(level)
        self._solve_coarsest()
        for level in ti.static(range(last - 1, -1, -1)):
            self._prolong(level)
            self._smooth(level)

    @ti.func
    def _restrict(self, level: ti.template()):
        """r_{l+1} = P^T t_l (t_l is 0 outside the grid), and the next level's first
        Jacobi sweep from 0."""
        cy, cx = ti.static(self.shapes[level + 1])
        t = ti.static(self.t[level])
        ti.loop_config(serialize=ti.static(self.serial))
        for J, I in ti.ndrange(cy, cx):
            j, i = 2 * J + PAD, 2 * I + PAD
            r = (t[j, i] + 0.5 * (t[j, i - 1] + t[j, i + 1] + t[j - 1, i] + t[j + 1, i])
                 + 0.25 * (t[j - 1, i - 1] + t[j - 1, i + 1] + t[j + 1, i - 1] + t[j + 1, i + 1]))
            self.r[level + 1][J + PAD, I + PAD] = r
            self.e[level + 1][J + PAD, I + PAD] = (self.omega[level + 1]
                                                   * self.inv_diag[level + 1][J, I] * r)

    @ti.func
    def _solve_coarsest(self):
        last = ti.static(self.levels - 1)
        cy, cx = ti.static(self.shapes[last])
        ti.loop_config(serialize=ti.static(self.serial))
        for J, I in ti.ndrange(cy, cx):
            acc = ti.Vector.zero(float, 3)
            for q in range(cy * cx):
                acc += (self.coarsest_inverse[J * cx + I, q]
                        * self.r[last][q // cx + PAD, q % cx + PAD])
            self.t[last][J + PAD, I + PAD] = acc

    @ti.func
    def _prolong(self, level: ti.template()):
        """e_l += P t_{l+1} on active nodes, coarse node by coarse node: fine (2J, 2I) and
        the three between it and the next coarse nodes."""
        fy, fx = ti.static(self.shapes[level])
        tc, e = ti.static(self.t[level + 1], self.e[level])
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
                        if self.inv_diag[level][j, i] > 0.0:
                            e[j + PAD, i + PAD] += ti.Vector([fine[2 * a + b, c]
                                                              for c in range(3)])

    @ti.func
    def _smooth(self, level: ti.template()):
        """t_l = e_l + omega D^-1 (r_l - A e_l)."""
        fy, fx = ti.static(self.shapes[level])
        ti.loop_config(serialize=ti.static(self.serial))
        for j, i in ti.ndrange(fy, fx):
            self.t[level][j + PAD, i + PAD] = (
                self.e[level][j + PAD, i + PAD] + self.omega[level] * self.inv_diag[level][j, i]
                * (self.r[level][j + PAD, i + PAD] - self._product(level, self.e[level], j, i)))

    @ti.kernel
    def _cycle(self):
        ny, nx = ti.static(self.shapes[0])
        ti.loop_config(serialize=ti.static(self.serial))
        for j, i in ti.ndrange(ny, nx):
            self.set_rhs(j, i, self.r[0][j + PAD, i + PAD])
        self.cycle()

    def vcycle(self, r):
        """One V-cycle on a (ny, nx, 3) NumPy right-hand side: B r (for tests and tools)."""
        padded = np.pad(r, ((PAD, PAD), (PAD, PAD), (0, 0)))
        self.r[0].from_numpy(padded.astype(runtime.numpy_real()))
        self._cycle()
        return self.t[0].to_numpy()[PAD:-PAD, PAD:-PAD]
