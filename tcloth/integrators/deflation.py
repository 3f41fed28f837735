"""A second level for projective dynamics' conjugate gradients with the contact planes in
its matrix (``contact/planes.py``): the active vertex pairs' directions deflated.

Each active pair k pushes along u_k = (n_k on its vertex a, -n_k on b), with a weight up
to ten times A's diagonal. The V-cycle that preconditions CG (``multigrid.MultigridPCG``)
is built from the springs alone and does not see those couplings: on the 64 x 64 fold
CG took about five times the iterations with the planes in A. With U the pairs' columns
(zero on pinned particles), E = U^T A U and Q = U E^+ U^T, the preconditioner

    z = B r + Q (r - A B r),   started from x0 = Q b,

is A-DEF2 of Tang, Nabben, Vuik and Erlangga ("Comparison of two-level preconditioners
derived from deflation, domain decomposition and multigrid methods", J. Sci. Comput. 39,
2009): it solves the pairs' subspace exactly at every iteration and leaves the V-cycle B
the rest. From that start its iterates are, in exact arithmetic, those of the balancing
preconditioner Q r + (I - QA) B (I - AQ) r, which took 16 and 21 CG iterations a solve
on the fold's global solves against the V-cycle's 36 and 40 (a NumPy re-solve of them;
``docs/contact.md``). A B r is needed only along U, so only at the pairs' vertices
(their stencils, not a whole product), and an iteration costs little more than before.

E is taken again for each active set (``prepare``, after every gather): A's springs
part from the solver's adjacency (its diagonal D_p plus the weights W of p's springs on
p, -W between spring neighbours), the planes' part from their Hessian sum_k w_k u_k
u_k^T = U W U^T, so U^T (U W U^T) U = G W G with G = U^T U. Two candidates can give one
vertex pair the same normal, so E^+ is NumPy's pseudo-inverse. The solver's only
couplings must be the planes (no constant matrix of a bending or membrane term:
projective then solves without the second level), its weights scalars and its diagonal
symmetric 3 x 3 blocks (``linalg.symmetric6``: a collider's stiffness acts along its
normal), so that a pair's diagonal part is n_k . D_p n_l.
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..runtime import serial
from .linalg import symmetric6_times

# more active pairs than this: the solve runs without the second level (E's entries cost
# k^2, its pseudo-inverse k^3; the 64 x 64 fold had 58 to 197)
MOST_PAIRS = 512
# E's eigenvalues below this times its largest are dropped (their directions are not
# deflated): E's entries are sums in float64, but of the solver's reals
RCOND = {"f64": 1e-10, "f32": 1e-5}


@ti.data_oriented
class PlaneDeflation:
    """The deflated pairs (``count``; 0: none, the solver's plain V-cycle) of a
    ``multigrid.MultigridPCG`` whose couplings are a projective step's planes, and
    the funcs its kernels call (``guess``, ``correct``)."""

    def __init__(self, solver, most=MOST_PAIRS):
        real = runtime.real()
        self.solver, self.most = solver, most
        self.rcond = RCOND["f64" if real == ti.f64 else "f32"]
        self.count = 0
        self.k = ti.field(ti.i32, shape=())
        self.pairs = ti.Vector.field(2, ti.i32, shape=most)
        self.n = ti.Vector.field(3, real, shape=most)
        self.w = ti.field(real, shape=most)
        self.e_inv = ti.field(real, shape=most * most)
        self.g = ti.field(real, shape=most)
        self.c = ti.field(real, shape=most)

    def prepare(self, rows):
        """Deflate the active pairs of ``rows`` (``contact.planes._Rows``) in the solves
        that follow, where there are at most ``most``; returns how many are deflated."""
        k = int(rows.count[None])
        self.count = k if k <= self.most else 0
        if self.count:
            springs, gram, w = np.zeros((k, k)), np.zeros((k, k)), np.zeros(k)
            self._blocks(rows, k, springs, gram, w)
            e = springs + gram @ (w[:, None] * gram)
            self._upload(np.linalg.pinv(e, rcond=self.rcond, hermitian=True), k)
        self.k[None] = self.count
        return self.count

    @ti.func
    def _free(self, p):
        return ti.cast(self.solver.inv_mass[p] > 0.0, float)

    @ti.kernel
    def _blocks(self, rows: ti.template(), k: ti.i32, springs: ti.types.ndarray(),
                gram: ti.types.ndarray(), w: ti.types.ndarray()):
        """The pairs copied from rows, and E's springs part and G into the arrays."""
        for i in range(k):
            self.pairs[i], self.n[i], self.w[i] = rows.pairs[i], rows.n[i], rows.w[i]
            w[i] = rows.w[i]
        for i, j in ti.ndrange(k, k):
            cosine = ti.cast(self.n[i].dot(self.n[j]), ti.f64)
            a_ij, g_ij = ti.cast(0.0, ti.f64), ti.cast(0.0, ti.f64)
            for a, b in ti.static([(0, 0), (0, 1), (1, 0), (1, 1)]):
                p, q = self.pairs[i][a], self.pairs[j][b]
                ends = ti.static((1 - 2 * a) * (1 - 2 * b)) * self._free(p) * self._free(q)
                sign = ends * cosine
                coupling = ti.cast(0.0, ti.f64)
                for e in range(self.solver.adj_start[p], self.solver.adj_start[p + 1]):
                    if p == q:
                        coupling += self.solver.weights[e]
                    elif self.solver.adj[e][1] == q:
                        coupling -= self.solver.weights[e]
                a_ij += sign * coupling
                if p == q:
                    own = self.n[i].dot(symmetric6_times(self.solver.diag[p], self.n[j]))
                    a_ij += ends * ti.cast(own, ti.f64)
                    g_ij += sign
            springs[i, j], gram[i, j] = a_ij, g_ij

    @ti.kernel
    def _upload(self, e_inv: ti.types.ndarray(), k: ti.i32):
        for i, j in ti.ndrange(k, k):
            self.e_inv[i * k + j] = e_inv[i, j]

    @ti.func
    def _solve_coarse(self, k):
        """c = E^+ g."""
        ti.loop_config(serialize=ti.static(serial(self.c)))
        for i in range(k):
            total = 0.0
            for j in range(k):
                total += self.e_inv[i * k + j] * self.g[j]
            self.c[i] = total

    @ti.func
    def _add_columns(self, v: ti.template(), k):
        """v += U c."""
        ti.loop_config(serialize=ti.static(serial(self.c)))
        for i in range(k):
            a, b = self.pairs[i][0], self.pairs[i][1]
            v[a] += self._free(a) * self.c[i] * self.n[i]
            v[b] -= self._free(b) * self.c[i] * self.n[i]

    @ti.func
    def guess(self):
        """The solver's x += Q b (its start x0 = Q b from x = 0)."""
        k = self.k[None]
        ti.loop_config(serialize=ti.static(serial(self.g)))
        for i in range(k):
            a, b = self.pairs[i][0], self.pairs[i][1]
            self.g[i] = self.n[i].dot(self._free(a) * self.solver.b[a]
                                      - self._free(b) * self.solver.b[b])
        self._solve_coarse(k)
        self._add_columns(self.solver.x, k)

    @ti.func
    def correct(self):
        """The solver's z += Q (r - A z), z = B r (the V-cycle's) on entry. The planes'
        part of A z at the pairs' vertices goes into the solver's ``extra`` there, where
        its product reads its couplings' part."""
        k = self.k[None]
        extra, z = ti.static(self.solver.extra, self.solver.z)
        ti.loop_config(serialize=ti.static(serial(self.g)))
        for i in range(k):
            extra[self.pairs[i][0]] = ti.Vector.zero(float, 3)
            extra[self.pairs[i][1]] = ti.Vector.zero(float, 3)
        ti.loop_config(serialize=ti.static(serial(self.g)))
        for i in range(k):
            a, b = self.pairs[i][0], self.pairs[i][1]
            push = self.w[i] * self.n[i].dot(z[a] - z[b]) * self.n[i]
            extra[a] += push
            extra[b] -= push
        ti.loop_config(serialize=ti.static(serial(self.g)))
        for i in range(k):
            a, b = self.pairs[i][0], self.pairs[i][1]
            left_a = self.solver.r[a] - self.solver._product(z, a)
            left_b = self.solver.r[b] - self.solver._product(z, b)
            self.g[i] = self.n[i].dot(self._free(a) * left_a - self._free(b) * left_b)
        self._solve_coarse(k)
        self._add_columns(z, k)
