"""The off-screen renderer's depth targets and how primitives are drawn into them.

A ``View`` maps the world onto a target's samples: the camera's (perspective) or the
light's (orthographic); a ``Target`` is a depth buffer of samples through a view.

Depth is the view's z, a point's distance along the view's forward direction: a ray's
parameter at the point where its direction is forward + sx right + sy up (perspective:
not a unit vector) or forward (orthographic), so that hits on one ray compare by depth.

  - Triangles are rasterised: each is projected and the samples of each of its rows
    between its edges (and one more each side) are tested against its three edge
    functions in the target's (column, row) plane, edges included, each edge evaluated
    from the same one of its ends in both triangles that share it (no sample falls
    between them). The depth there is interpolated, of 1/z in perspective (linear on the
    screen). So a triangle costs what it covers.
  - Spheres and colliders are ray-cast at the samples of the projected box of a bounding
    sphere (``Target.sphere``); colliders that never move, and the ground, once at every
    sample (``cast``).

A sample's hit is kept with ``atomic_min``: in the camera's target the key of
``raycast.key`` (depth bits over the primitive's id: the nearest wins, ties go to the
smaller id, whatever the order of the threads); in the shadow map the depth alone, with
the least of each tile's (``summarise``). What the geometry that never moves leaves in a
target is drawn once (``keep``) and is where every frame starts (``restore``).
"""
import numpy as np
import taichi as ti

from ..geometry import raycast
from ..geometry.shapes import SHAPES

SKY_ID = 2147483647
SKY_KEY = (2147483647 << 32) | SKY_ID
GROUND_ID = 2147483646
COLLIDER_ID = 1 << 30      # collider row k has id COLLIDER_ID + k
FAR = 1e30                 # the depth of a shadow-map texel that sees nothing
NEAR = 1e-3                # m: a triangle with a corner nearer the camera is not drawn
SLACK = 2.0                # pixels added round a projected bounding sphere
TILE = 16                  # samples a side of a depth-only target's tiles (``summarise``)


@ti.data_oriented
class View:
    """A projection of the world onto a height x width target's samples, its numbers
    compiled in.

    The sample at (row, col) is at sx = (2 (col + 1/2) / width - 1) scale_x,
    sy = (1 - 2 (row + 1/2) / height) scale_y: its ray runs from ``origin`` along
    forward + sx right + sy up (perspective) or from origin + sx right + sy up along
    ``forward``.

    Args:
        origin, forward, right, up: (3,) m and unit vectors, right and up across forward.
        scale_x, scale_y: half the view's width and height at depth 1 (perspective) or in
            metres (orthographic). perspective: bool. height, width: samples.
    """

    def __init__(self, origin, forward, right, up, scale_x, scale_y, perspective, height,
                 width):
        def f32(v):
            return tuple(float(c) for c in np.asarray(v, dtype=np.float32).ravel())
        self.origin, self.forward, self.right, self.up = (f32(v) for v in (origin, forward,
                                                                          right, up))
        self.perspective = bool(perspective)
        self.height, self.width = int(height), int(width)
        # sx = col kx + bx, sy = row ky + by; and back: col = sx ax + cx, row = sy ay + cy
        self.kx, self.bx, self.ky, self.by, self.ax, self.cx, self.ay, self.cy = f32([
            2 * scale_x / width, scale_x / width - scale_x, -2 * scale_y / height,
            scale_y - scale_y / height, width / (2 * scale_x), width / 2 - 0.5,
            -height / (2 * scale_y), height / 2 - 0.5])

    @ti.func
    def vec(self, v: ti.template()):
        """One of the view's vectors (origin, forward, right, up) as a float32 vector."""
        return ti.Vector([ti.static(v[0]), ti.static(v[1]), ti.static(v[2])], ti.f32)

    @ti.func
    def ray(self, row, col):
        """(origin, direction) of the ray of sample (row, col)."""
        across = ((col * ti.static(self.kx) + ti.static(self.bx)) * self.vec(self.right)
                  + (row * ti.static(self.ky) + ti.static(self.by)) * self.vec(self.up))
        o, d = self.vec(self.origin), self.vec(self.forward)
        if ti.static(self.perspective):
            d += across
        else:
            o += across
        return o, d

    @ti.func
    def project(self, p):
        """(col, row, depth) of point p (sample (r, c) is at (c, r))."""
        q = ti.cast(p, ti.f32) - self.vec(self.origin)
        z = q.dot(self.vec(self.forward))
        u, v = q.dot(self.vec(self.right)), q.dot(self.vec(self.up))
        if ti.static(self.perspective):
            inv = 1.0 / z
            u, v = u * inv, v * inv
        return ti.Vector([u * ti.static(self.ax) + ti.static(self.cx),
                          v * ti.static(self.ay) + ti.static(self.cy), z])

    @ti.func
    def reach(self, p, q, radius):
        """Pixels from q, the projection of p, within which every point of the sphere of
        ``radius`` about p projects (plus SLACK); 1e9 where the camera is within it."""
        out = radius * ti.static(abs(self.ay)) + SLACK
        if ti.static(self.perspective):
            # |d(x/z)| <= radius |p - origin| / (z (z - radius)) for points within radius
            out = 1e9
            if q[2] > radius + NEAR:
                out = (radius * (ti.cast(p, ti.f32) - self.vec(self.origin)).norm()
                       / (q[2] * (q[2] - radius)) * ti.static(abs(self.ay)) + SLACK)
        return out


@ti.func
def bead(x, ends, share, k):
    """The centre of sphere k of a list: (1 - share[k]) x[ends[k][0]] + share[k] x[ends[k][1]]
    (a particle where both ends are it, or a bead along a spring), float32."""
    e, s = ends[k], share[k]
    return ti.cast((1.0 - s) * x[e[0]] + s * x[e[1]], ti.f32)


@ti.func
def _edge(p, q):
    """The edge from p to q as (start x, start y, dx, dy, sign): started at the smaller of
    its ends (x, then y), so that both triangles that share it evaluate it alike."""
    swap = p[0] > q[0] or (p[0] == q[0] and p[1] > q[1])
    lo, hi, sign = p, q, 1.0
    if swap:
        lo, hi, sign = q, p, -1.0
    return ti.Vector([lo[0], lo[1], hi[0] - lo[0], hi[1] - lo[1], sign])


@ti.func
def _side(e, col, row):
    """Twice the signed area of (p, q, (col, row)) for the edge e from p to q."""
    return e[4] * ((row - e[1]) * e[2] - (col - e[0]) * e[3])


@ti.func
def _span(e, row, area, span):
    """``span`` (first, last column) narrowed to where row ``row`` lies on the inner side
    (that of a triangle of signed ``area``) of edge e: _side(e, col, row) = a - b col."""
    g = 1.0 if area > 0.0 else -1.0
    b = g * e[4] * e[3]
    a = g * e[4] * ((row - e[1]) * e[2] + e[0] * e[3])
    if b > 0.0:
        span[1] = ti.min(span[1], a / b)
    elif b < 0.0:
        span[0] = ti.max(span[0], a / b)
    elif a < 0.0:
        span[1] = span[0] - 2.0
    return span


@ti.data_oriented
class Target:
    """A buffer of the nearest hit at each sample of ``view``: keys
    (``ids``: the camera) or depths (the shadow map); ``static``: what ``keep`` stored.
    ``ground``: the height (m) of a ground plane to cast, or False. A depth-only target
    also keeps ``nearest``: per tile of TILE x TILE samples, the least depth in it and in
    the row and column after it (``summarise``), so that a 2 x 2 block of samples that
    starts in a tile is no nearer than that."""

    def __init__(self, view, ids, ground=False):
        self.view, self.height, self.width, self.ids = view, view.height, view.width, ids
        self.ground, self.has_ground = ground, ground is not False
        dtype = ti.i64 if ids else ti.f32
        self.depth = ti.field(dtype, shape=(self.height, self.width))
        self.static = ti.field(dtype, shape=(self.height, self.width))
        self.nearest = ti.field(ti.f32, shape=(-(-self.height // TILE), -(-self.width // TILE)))

    @ti.kernel
    def clear(self):
        for r, c in self.depth:
            if ti.static(self.ids):
                self.depth[r, c] = ti.i64(SKY_KEY)
            else:
                self.depth[r, c] = FAR

    def keep(self):
        self.static.copy_from(self.depth)

    def restore(self):
        self.depth.copy_from(self.static)

    @ti.kernel
    def summarise(self):
        """Each tile's ``nearest`` depth (class docstring)."""
        for tr, tc in self.nearest:
            least = FAR
            for r in range(tr * TILE, ti.min(tr * TILE + TILE + 1, ti.static(self.height))):
                for c in range(tc * TILE, ti.min(tc * TILE + TILE + 1, ti.static(self.width))):
                    least = ti.min(least, self.depth[r, c])
            self.nearest[tr, tc] = least

    @ti.func
    def ray(self, row, col):
        return self.view.ray(row, col)

    @ti.func
    def project(self, p):
        return self.view.project(p)

    @ti.func
    def put(self, row, col, z, prim):
        """A hit at depth z > 0 of primitive ``prim``."""
        if ti.static(self.ids):
            ti.atomic_min(self.depth[row, col], raycast.key(z, prim))
        else:
            ti.atomic_min(self.depth[row, col], ti.cast(z, ti.f32))

    @ti.func
    def triangle(self, a, b, c, prim):
        """Rasterise triangle (a, b, c) (module docstring)."""
        pa, pb, pc = self.project(a), self.project(b), self.project(c)
        if not ti.static(self.view.perspective) or (pa[2] > NEAR and pb[2] > NEAR
                                                    and pc[2] > NEAR):
            e_bc, e_ca, e_ab = _edge(pb, pc), _edge(pc, pa), _edge(pa, pb)
            area = _side(e_ab, pc[0], pc[1])
            if abs(area) > 1e-9:
                lo, hi = ti.min(pa, pb, pc), ti.max(pa, pb, pc)
                inv = 1.0 / area
                depth = ti.Vector([pa[2], pb[2], pc[2]])
                if ti.static(self.view.perspective):
                    depth = 1.0 / depth
                first = ti.max(ti.cast(ti.floor(lo[0]), ti.i32), 0)
                last = ti.min(ti.cast(ti.ceil(hi[0]), ti.i32), ti.static(self.width) - 1)
                for r in range(ti.max(ti.cast(ti.floor(lo[1]), ti.i32), 0),
                               ti.min(ti.cast(ti.ceil(hi[1]), ti.i32),
                                      ti.static(self.height) - 1) + 1):
                    # the columns of row r inside all three edges, a column wider
                    span = ti.Vector([lo[0], hi[0]])
                    for e in ti.static((e_bc, e_ca, e_ab)):
                        span = _span(e, r, area, span)
                    for col in range(ti.max(ti.cast(ti.ceil(span[0]), ti.i32) - 1, first),
                                     ti.min(ti.cast(ti.floor(span[1]), ti.i32) + 1, last) + 1):
                        w = ti.Vector([_side(e_bc, col, r), _side(e_ca, col, r),
                                       _side(e_ab, col, r)]) * inv
                        if w.min() >= 0.0:
                            z = w.dot(depth)
                            if ti.static(self.view.perspective):
                                z = 1.0 / z
                            self.put(r, col, z, prim)

    @ti.kernel
    def triangles(self, x: ti.template(), tris: ti.template(), begin: ti.i32, end: ti.i32,
                  first_id: ti.i32):
        """Triangles begin .. end - 1 of ``tris`` (corner indices into ``x``), ids from
        ``first_id`` + begin."""
        for k in range(begin, end):
            i = tris[k]
            self.triangle(x[i[0]], x[i[1]], x[i[2]], first_id + k)

    @ti.func
    def sphere(self, centre, radius, prim):
        """Ray-cast a sphere at the samples its projection can cover."""
        q = self.project(centre)
        reach = self.view.reach(centre, q, radius)
        if not ti.static(self.view.perspective) or q[2] > radius + NEAR:
            for r in range(ti.max(ti.cast(ti.floor(q[1] - reach), ti.i32), 0),
                           ti.min(ti.cast(ti.ceil(q[1] + reach), ti.i32),
                                  ti.static(self.height) - 1) + 1):
                for col in range(ti.max(ti.cast(ti.floor(q[0] - reach), ti.i32), 0),
                                 ti.min(ti.cast(ti.ceil(q[0] + reach), ti.i32),
                                        ti.static(self.width) - 1) + 1):
                    o, d = self.ray(r, col)
                    length = d.norm()
                    t = raycast.hit_sphere(o, d / length, centre, radius)
                    if t > 0.0:
                        self.put(r, col, t / length, prim)

    @ti.kernel
    def spheres(self, x: ti.template(), ends: ti.template(), share: ti.template(),
                count: ti.i32, radius: ti.f32, first_id: ti.i32):
        """Spheres of ``radius`` at (1 - share[k]) x[ends[k][0]] + share[k] x[ends[k][1]],
        ids from ``first_id``."""
        for k in range(count):
            self.sphere(bead(x, ends, share, k), radius, first_id + k)

    @ti.func
    def _drawn(self, shape: ti.template()):
        """Whether colliders of this shape are cast here: not meshes (rasterised), nor
        checkered ones (planes) in the shadow map (they receive shadows, cast none)."""
        return ti.static(not SHAPES[shape].meshed and (self.ids or not SHAPES[shape].checkered))

    @ti.kernel
    def cast(self, colliders: ti.template(), moving: ti.template(), time: ti.f32):
        """At every sample: the ground and the colliders that do not move (moving[k] == 0),
        row k's id COLLIDER_ID + k."""
        for r, c in self.depth:
            o, d = self.ray(r, c)
            length = d.norm()
            u = d / length
            best, best_id = FAR, SKY_ID
            if ti.static(self.has_ground):
                if u[1] < -1e-6:
                    t = (ti.static(float(self.ground)) - o[1]) / u[1]
                    if t > 0.0:
                        best, best_id = t, GROUND_ID
            for g in ti.static(colliders.groups):
                if self._drawn(g.shape):
                    for k in range(g.first, g.first + g.count):
                        if moving[k] == 0:
                            t = ti.cast(colliders.ray_hit(g.shape, colliders.data[k], o, u,
                                                          time), ti.f32)
                            if 0.0 < t < best:
                                best, best_id = t, COLLIDER_ID + k
            if best_id != SKY_ID:
                self.put(r, c, best / length, best_id)

    @ti.kernel
    def cast_moving(self, colliders: ti.template(), rows: ti.template(),
                    radii: ti.template(), count: ti.i32, time: ti.f32):
        """The colliders of rows[0 .. count - 1], each at the samples its bounding sphere
        (radius radii[j] about its centre, which moves with its velocity) can cover."""
        for j, r in ti.ndrange(count, ti.static(self.height)):
            k = rows[j]
            for g in ti.static(colliders.groups):
                if self._drawn(g.shape):
                    if g.first <= k < g.first + g.count:
                        col = colliders.data[k]
                        centre = ti.cast(col.center + time * col.velocity, ti.f32)
                        q = self.project(centre)
                        reach = self.view.reach(centre, q, radii[j])
                        c0 = ti.max(ti.cast(ti.floor(q[0] - reach), ti.i32), 0)
                        c1 = ti.min(ti.cast(ti.ceil(q[0] + reach), ti.i32),
                                    ti.static(self.width) - 1)
                        if r < q[1] - reach or r > q[1] + reach:
                            c1 = -1
                        for c in range(c0, c1 + 1):
                            o, d = self.ray(r, c)
                            length = d.norm()
                            t = ti.cast(colliders.ray_hit(g.shape, col, o, d / length, time),
                                        ti.f32)
                            if t > 0.0:
                                self.put(r, c, t / length, COLLIDER_ID + k)
