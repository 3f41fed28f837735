"""What both renderers (the off-screen one and the window) draw, and in which colours:
the cloth where it is drawn (``DrawnCloth``: at its particles, out of the colliders it
rests on), spheres for free particles and beads along springs between them (ropes), and
the front and back colours of each cloth. The spheres and colours are plain NumPy from
the scene, made once per renderer."""
import numpy as np
import taichi as ti

from ..geometry import raycast
from ..errors import SceneError
from ..scene.meshcollider import moves

CONTACT_REACH = 3.0   # a particle within this many thicknesses of a collider rests on it
SAMPLES = 4           # a triangle's test points: a barycentric grid, this many steps a side
REFINE = 4            # then a search about the nearest of them, halving its step this often
LIFT_PASSES = 3       # Jacobi passes of DrawnCloth's lift
CLEARANCE = 0.25      # drawn cloth keeps at least this many thicknesses off a collider

FRONT_COLOUR = (0.85, 0.28, 0.18)
BACK_COLOUR = (0.20, 0.42, 0.80)
PARTICLE_COLOUR = (0.95, 0.78, 0.25)
COLLIDER_COLOUR = (0.50, 0.58, 0.66)


def cloth_palette(cloth_colours, cloths):
    """(cloths, 2, 3) front and back RGB per cloth: the defaults, or ``cloth_colours``
    checked (one (front, back) pair of values in [0, 1] per cloth)."""
    palette = np.array(cloth_colours if cloth_colours is not None else
                       [(FRONT_COLOUR, BACK_COLOUR)] * cloths, dtype=np.float64)
    if palette.size == 0:
        palette = palette.reshape(0, 2, 3)
    if palette.shape != (cloths, 2, 3) or not np.all((palette >= 0) & (palette <= 1)):
        raise SceneError(f"cloth_colours must hold one (front, back) pair of RGB values in "
                         f"[0, 1] per cloth ({cloths} cloths; got {cloth_colours!r})")
    return palette


def collider_moves(collider):
    """Whether a scene collider moves (its drawn mesh changes with time)."""
    return moves(collider) if collider["kind"] == "mesh" else bool(
        np.any(np.asarray(collider["velocity"]) != 0))


def particle_spheres(scene, particle_radius, extent):
    """(spheres (S, 3): end particle i, end particle j, fraction s along i -> j; radius).

    Every particle outside a cloth is a sphere (i = j, s = 0); each spring between two
    such particles gets beads spaced about one radius apart at its initial length.
    particle_radius None picks 0.35 times the median rest length of those springs, or
    2 % of the scene's extent without them."""
    x0 = scene.positions
    in_cloth = np.zeros(scene.num_particles, dtype=bool)
    for c in scene.cloths:
        in_cloth[c.particles.ravel()] = True
    free = np.flatnonzero(~in_cloth)
    sp = scene.springs
    free_spring = ~in_cloth[sp["pairs"][:, 0]] & ~in_cloth[sp["pairs"][:, 1]]
    line = sp["pairs"][free_spring]
    if particle_radius is None:
        rest = sp["rest_length"][free_spring]
        particle_radius = 0.35 * float(np.median(rest)) if len(rest) else 0.02 * extent
    radius = float(particle_radius)
    beads = [np.stack([np.full(k, i), np.full(k, j), (np.arange(k) + 1) / (k + 1)], 1)
             for (i, j), k in zip(line, np.ceil(np.linalg.norm(
                 x0[line[:, 0]] - x0[line[:, 1]], axis=1) / radius).astype(int))]
    spheres = np.concatenate([np.stack([free, free, np.zeros(len(free))], 1)] + beads)
    return spheres, radius


@ti.data_oriented
class DrawnCloth:
    """Where both renderers draw the cloth: at its particles, except where its flat
    triangles would cut into a collider they rest on.

    Contact keeps the particles a collider's thickness out (the cloth's half thickness),
    but a flat triangle between particles lying on a curved collider is a chord that dips
    below that by its sagitta, and one across a box's edge or corner cuts it off (by up
    to a quarter of its width), so that the collider would show through and poke out
    past the cloth's outline (a rod's edges as grey strips, a capsule's caps). So a
    triangle with a particle within ``CONTACT_REACH`` thicknesses T of a switched-on
    collider is drawn at least max(r, T) - (1 - ``CLEARANCE``) T from it, r the nearest
    of its particles' distances (``CLEARANCE`` T where they rest at the thickness or
    nearer). Where a test point (a grid, and a local search about its nearest point: the
    distance is convex over a triangle for convex shapes) is nearer, its particles move
    out along the collider's normal, each by the most any of its triangles asks
    (``LIFT_PASSES`` times), at most half the triangle's longest edge plus T. A triangle
    on a flat face is not moved, the colliders are drawn where they are, and cloth layers
    keep their order (a cloth resting farther out is kept farther out).

    Each particle's distance from each collider is found once an update; a test point's
    is searched (a mesh's hierarchy) only as far as can change what is asked: below
    where it asks a move or a search, and down to the deepest it can lie inside (the
    distance changes no faster than the point moves, from the nearest particle's).

    Args:
        colliders: the model's ``ColliderTable``. triangles: (T, 3) particle indices.
        particle_count: particles in the model.
    """

    def __init__(self, colliders, triangles, particle_count):
        self.colliders = colliders
        self.count = len(triangles)
        self.x = ti.Vector.field(3, ti.f32, shape=max(particle_count, 1))   # drawn, m
        # per particle: the largest move asked of it, float bits over the collider's index
        self.lift = ti.field(ti.i64, shape=max(particle_count, 1))
        self.moved = ti.field(ti.i32, shape=max(particle_count, 1))   # by the last pass
        # per particle and collider: its distance and normal at the update's positions
        shape = (max(particle_count, 1), max(colliders.count, 1))
        self.rest = ti.field(ti.f32, shape=shape)
        self.rest_n = ti.Vector.field(3, ti.f32, shape=shape)
        self.tris = ti.Vector.field(3, ti.i32, shape=max(self.count, 1))
        if self.count:
            self.tris.from_numpy(np.asarray(triangles, dtype=np.int32))

    def update(self, x, time):
        """The drawn positions (``self.x``, float32) of particle positions ``x`` (a
        Taichi field) at time ``time`` (s)."""
        self._copy(x)
        if self.colliders.count and self.count:
            self._rests(x, time)
            for _ in range(LIFT_PASSES):
                self._lifts(x, time)
                self._move(time)
        return self.x

    @ti.kernel
    def _copy(self, x: ti.template()):
        for p in self.x:
            self.x[p] = ti.cast(x[p], ti.f32)
            self.moved[p] = 1

    @ti.kernel
    def _rests(self, x: ti.template(), time: ti.f32):
        """Each particle's distance and normal from each collider."""
        for p in range(self.rest.shape[0]):
            for g in ti.static(self.colliders.groups):
                for m in range(g.first, g.first + g.count):
                    phi, n = self.colliders.distance(g.shape, self.colliders.data[m], x[p], time)
                    self.rest[p, m] = ti.cast(phi, ti.f32)
                    self.rest_n[p, m] = ti.cast(n, ti.f32)

    @ti.kernel
    def _lifts(self, x: ti.template(), time: ti.f32):
        """For every resting triangle: at its test points nearer to the collider than it
        is drawn, and at the nearest point of a local search from the nearest of them (a
        box's corner falls between test points), move each corner so that the point would
        come out that far (``_ask``)."""
        for p in self.lift:
            self.lift[p] = 0
        for k in range(self.count):
            i = self.tris[k]
            # a triangle none of whose corners the last pass moved asks what it asked
            # then: nothing (it would have moved them)
            if self.moved[i[0]] + self.moved[i[1]] + self.moved[i[2]] > 0:
                self._lift(x, i, time)

    @ti.func
    def _lift(self, x, i, time):
        """A resting triangle i's asks (``_lifts``)."""
        a, b, c = self.x[i[0]], self.x[i[1]], self.x[i[2]]
        longest = ti.max((b - a).norm(), (c - b).norm(), (a - c).norm())
        for g in ti.static(self.colliders.groups):
            for m in range(g.first, g.first + g.count):
                col = self.colliders.data[m]
                rest, nearest = self.rest[i[0], m], i[0]
                normals = ti.Matrix.rows([self.rest_n[i[0], m], self.rest_n[i[1], m],
                                          self.rest_n[i[2], m]])
                for j in ti.static(range(1, 3)):
                    if self.rest[i[j], m] < rest:
                        rest, nearest = self.rest[i[j], m], i[j]
                thickness = ti.cast(col.thickness, ti.f32)
                if col.stiffness > 0.0 and rest < CONTACT_REACH * thickness:
                    target = ti.max(rest, thickness) - (1.0 - CLEARANCE) * thickness
                    cap = 0.5 * longest + thickness
                    # a test point is no deeper than rest less its distance from the
                    # nearest particle (at most its farthest corner's): searched to a
                    # thickness past that and past where it would ask
                    q = ti.cast(x[nearest], ti.f32)
                    apart = ti.max((a - q).norm(), (b - q).norm(), (c - q).norm())
                    beyond = ti.max(target + 0.6 * longest / SAMPLES, apart - rest, 0.0)
                    near, nu, nv = 1e30, 0.0, 0.0
                    for s in range(SAMPLES + 1):
                        for t in range(SAMPLES + 1 - s):
                            u, v = s / SAMPLES, t / SAMPLES
                            phi = _distance(self.colliders, g.shape, col, a, b, c, u,
                                            v, time, beyond)
                            if phi < near:
                                near, nu, nv = phi, u, v
                            self._ask(i, u, v, target - phi, normals, cap, m)
                    # every point is within 0.6 longest / SAMPLES of a test point
                    # (the distance changes no faster than the point moves)
                    if near - 0.6 * longest / SAMPLES < target:
                        step = 0.5 / SAMPLES
                        for level in range(REFINE):
                            bu, bv = nu, nv
                            for nb in range(6):
                                du, dv = _neighbour(nb)
                                u, v = bu + du * step, bv + dv * step
                                if u >= 0.0 and v >= 0.0 and u + v <= 1.0:
                                    phi = _distance(self.colliders, g.shape, col, a, b,
                                                    c, u, v, time, beyond)
                                    if phi < near:
                                        near, nu, nv = phi, u, v
                            step *= 0.5
                        self._ask(i, nu, nv, target - near, normals, cap, m)

    @ti.func
    def _ask(self, i, u, v, deficit, normals, cap, m):
        """Ask the corners of triangle i to move so that its point of weights
        w = (1 - u - v, u, v) comes out by ``deficit`` from collider m, each along its
        particle's normal (the rows of ``normals``), whose component on the point's
        outward direction (those normals weighted by w) is what moves the point; at most
        ``cap``."""
        if deficit > 0.0:
            w = ti.Vector([1.0 - u - v, u, v], ti.f32)
            out = normals.transpose() @ w
            along = ti.Vector([1.0, 1.0, 1.0], ti.f32)
            if out.norm() > 1e-6:
                along = normals @ out.normalized()
            for j in ti.static(range(3)):
                if w[j] > 0.0:
                    move = ti.min(deficit * w[j] / w.dot(w) / ti.max(along[j], 0.3), cap)
                    ti.atomic_max(self.lift[i[j]], raycast.key(move, m))

    @ti.kernel
    def _move(self, time: ti.f32):
        """Each particle asked to move: out along its collider's normal."""
        for p in self.x:
            key = self.lift[p]
            self.moved[p] = ti.select(key > 0, 1, 0)
            if key > 0:
                m = raycast.key_id(key)
                for g in ti.static(self.colliders.groups):
                    if g.first <= m < g.first + g.count:
                        _, n = self.colliders.distance(g.shape, self.colliders.data[m],
                                                       self.x[p], time)
                        self.x[p] += raycast.key_t(key) * ti.cast(n, ti.f32)


@ti.func
def _neighbour(k):
    """The k-th of the six neighbours (du, dv) of a point of a triangular grid."""
    du, dv = 1, -1
    if k == 0:
        du, dv = 1, 0
    elif k == 1:
        du, dv = -1, 0
    elif k == 2:
        du, dv = 0, 1
    elif k == 3:
        du, dv = 0, -1
    elif k == 5:
        du, dv = -1, 1
    return du, dv


@ti.func
def _distance(table: ti.template(), shape: ti.template(), col, a, b, c, u, v, time, beyond):
    """Signed distance (float32) from collider ``col`` of the point of weights
    (1 - u - v, u, v) of triangle (a, b, c), searched no farther than ``beyond`` past its
    thickness (``ColliderTable.contact``)."""
    phi, _n, _u = table.contact(shape, col, (1.0 - u - v) * a + u * b + v * c, time, beyond)
    return ti.cast(phi, ti.f32)
