"""The adjoint of projective dynamics' self-contact projection (``ProjectionAdjoint``).

After its iterations, projective dynamics projects the penetrating contacts
(``terms/self_contact.py``): Gauss-Seidel passes, each correction moving a contact's four
particles by alpha_k / m_k times an impulse (apart to the thickness, or removing the
approaching normal velocity with Coulomb friction). A correction is a function of its
four particles' positions, velocities and inverse masses before it; the closest points
(alpha), the normal and the depth move with the positions. The forward run keeps each
correction's inputs (``self_contact.ProjectionLog``), and the backward run:

  - replays every correction from its inputs in one kernel (the term's own
    ``projection_impulse``) and forms its Jacobian by Taichi's reverse mode, one seeded
    launch per output component (24), all corrections at once;
  - pulls the adjoints back through the corrections in reverse order, the Jacobians'
    transposes applied one after the other (``pull_back``), then through the vertex
    normals at the solver's end that the velocity pass's surfaces' normals read
    (``normals.contact_normal``; an edge-edge contact's, logged with the correction).

This is the derivative of what the forward run computed: the corrections that fired are
the active set (frozen), each one's branch (the closest points' region, static or
kinetic friction, the closest points' or the surfaces' normal) the one it took. The
solver's end of the step before the projection is the corrections' first inputs
(``before``).
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..geometry.proximity import contact_weights
from ..contact.normals import SURFACE, logged_kind, surface_normal
from ..terms.self_contact import projection_impulse

OUTPUTS = 24        # a correction's four positions and four velocities after it
INPUTS = 34         # its four positions, velocities and inverse masses before it, and
                    # the two sides' vertex normals (the velocity pass's normal)


@ti.data_oriented
class ProjectionAdjoint:
    """Vector-Jacobian products of one step's projection (``pull_back``) over the
    self-collision table ``table`` (its thickness and friction), for logs of up to
    ``capacity`` corrections."""

    def __init__(self, table, capacity):
        real = runtime.real()
        self.table, self.capacity = table, capacity
        self.kind, self.velocity = (ti.field(ti.i32, shape=capacity) for _ in range(2))
        self.x, self.v, self.x_out, self.v_out = (
            ti.Vector.field(3, real, shape=(capacity, 4), needs_grad=True) for _ in range(4))
        self.sides = ti.Vector.field(3, real, shape=(capacity, 2), needs_grad=True)
        self.inv = ti.field(real, shape=(capacity, 4), needs_grad=True)
        self.count = ti.field(ti.i32, shape=())

    @ti.kernel
    def _replay(self):
        """Each kept correction again from its inputs: x_out, v_out."""
        for e in range(self.count[None]):
            kind, choice = logged_kind(self.kind[e])
            p = ti.Matrix.rows([self.x[e, 0], self.x[e, 1], self.x[e, 2], self.x[e, 3]])
            alpha = contact_weights(kind, self.x[e, 0], self.x[e, 1], self.x[e, 2],
                                    self.x[e, 3])
            g, v_rel, w = ti.Vector.zero(float, 3), ti.Vector.zero(float, 3), 0.0
            for j in ti.static(range(4)):
                g += alpha[j] * self.x[e, j]
                v_rel += alpha[j] * self.v[e, j]
                w += alpha[j] * alpha[j] * self.inv[e, j]
            prm = ti.static(self.table.params)
            n = g / g.norm()
            if choice == SURFACE:
                n = surface_normal(kind, p, self.sides[e, 0], self.sides[e, 1], n)
            impulse = ti.Vector.zero(float, 3)
            if self.velocity[e]:
                _pass, impulse = projection_impulse(prm, g, n, w, v_rel, True)
            else:
                _pass, impulse = projection_impulse(prm, g, n, w, v_rel, False)
            s = ti.cast(self.velocity[e], float)
            for j in ti.static(range(4)):
                change = self.inv[e, j] * alpha[j] * impulse
                self.x_out[e, j] = self.x[e, j] + (1.0 - s) * change
                self.v_out[e, j] = self.v[e, j] + s * change

    @ti.kernel
    def _seed(self, out: ti.template(), j: ti.i32, axis: ti.i32):
        """out's adjoint: 1 in component ``axis`` of particle slot j of every correction."""
        for e, k in out:
            unit = ti.Vector.zero(float, 3)
            if k == j:
                unit[axis] = 1.0
            out.grad[e, k] = unit

    def jacobians(self, entries, inv_mass):
        """Each correction's Jacobian (k, 24, 34): its outputs (four positions, then four
        velocities) in its inputs (four positions, four velocities, four inverse masses,
        the two sides' vertex normals)."""
        ids, kind, velocity, x, v, sides = entries
        k, npr = len(kind), runtime.numpy_real()
        for field, values in ((self.kind, kind), (self.velocity, velocity), (self.x, x),
                              (self.v, v), (self.inv, inv_mass[ids]), (self.sides, sides)):
            padded = np.zeros((self.capacity,) + values.shape[1:],
                              dtype=npr if values.dtype.kind == "f" else values.dtype)
            padded[:k] = values
            field.from_numpy(padded)
        self.count[None] = k
        self._replay()
        jac = np.empty((k, OUTPUTS, INPUTS))
        for row in range(OUTPUTS):
            out, other = (self.x_out, self.v_out) if row < 12 else (self.v_out, self.x_out)
            for field in (self.x, self.v, self.inv, self.sides):
                field.grad.fill(0)
            other.grad.fill(0)
            self._seed(out, row % 12 // 3, row % 3)
            self._replay.grad()
            jac[:, row, :12] = self.x.grad.to_numpy()[:k].reshape(k, 12)
            jac[:, row, 12:24] = self.v.grad.to_numpy()[:k].reshape(k, 12)
            jac[:, row, 24:28] = self.inv.grad.to_numpy()[:k]
            jac[:, row, 28:] = self.sides.grad.to_numpy()[:k].reshape(k, 6)
        return jac

    def pull_back(self, entries, inv_mass, x1, x_bar, v_bar):
        """The adjoints of the projection's input (the solver's x1, v1; ``x1`` the former)
        from those of its output, its corrections' in reverse order, then the vertex
        normals' at x1 that the velocity pass read (``vertex_normals_vjp``), and of the
        inverse masses: (x_bar, v_bar, inv_mass_bar)."""
        ids = entries[0]
        jac = self.jacobians(entries, inv_mass)
        x_bar, v_bar = x_bar.copy(), v_bar.copy()
        inv_bar = np.zeros(len(inv_mass))
        normals_bar = np.zeros_like(x_bar)
        for e in range(len(ids) - 1, -1, -1):
            q = ids[e]
            y = np.concatenate((x_bar[q].ravel(), v_bar[q].ravel()))
            z = y @ jac[e]
            x_bar[q] = z[:12].reshape(4, 3)
            v_bar[q] = z[12:24].reshape(4, 3)
            inv_bar[q] += z[24:28]
            for side in range(2):
                normals_bar[q[2 * side:2 * side + 2]] += z[28 + 3 * side:31 + 3 * side]
        triangles = self.table.triangles.to_numpy()[:self.table.triangle_count]
        return x_bar + vertex_normals_vjp(triangles, x1, normals_bar), v_bar, inv_bar


def vertex_normals_vjp(triangles, x, normals_bar):
    """The adjoint of the positions x from that of ``normals.vertex_normals`` at x: each
    triangle's c = (x_1 - x_0) x (x_2 - x_0), summed at its corners, so c's adjoint is
    the sum of its corners' and e_1 = x_1 - x_0 gets e_2 x c_bar, e_2 gets c_bar x e_1."""
    out = np.zeros_like(x)
    if len(triangles):
        c_bar = normals_bar[triangles].sum(axis=1)
        e1 = x[triangles[:, 1]] - x[triangles[:, 0]]
        e2 = x[triangles[:, 2]] - x[triangles[:, 0]]
        e1_bar, e2_bar = np.cross(e2, c_bar), np.cross(c_bar, e1)
        np.add.at(out, triangles[:, 1], e1_bar)
        np.add.at(out, triangles[:, 2], e2_bar)
        np.add.at(out, triangles[:, 0], -e1_bar - e2_bar)
    return out


def before(entries, end, velocities=False):
    """The solver's end of the step before the projection, its positions (or its
    velocities), from the projection's end (``end``) and the corrections' inputs: each
    particle's where its first correction found it."""
    ids, _, _, x, v = entries[:5]
    particles, first = np.unique(ids.ravel(), return_index=True)
    start = end.copy()
    start[particles] = (v if velocities else x).reshape(-1, 3)[first]
    return start
