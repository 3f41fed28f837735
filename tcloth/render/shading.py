"""The off-screen renderer's shading pass: the colour of each pixel from what its samples
see (``Shading``, a part of ``render.Renderer``, whose targets and buffers it reads).

Lambert + hemisphere ambient + a little specular, shadows from the shadow map; cloth front
and back in two colours, checkered ground and planes. A pixel whose samples all see one
surface (one primitive, or triangles of one cloth or mesh that share a corner, lie within
14 degrees of each other's plane and, for cloth, show the camera the same side) gets that
surface's colour averaged over its samples (the checkers' squares), lit once at their
mean point with the normal there (the mean of the triangles' at their samples); any other
pixel is the mean of its samples each shaded and lit. The shadow map is read at every
sample, so that shadows' edges keep their anti-aliasing; the rest of the light varies
smoothly across a surface, so the two differ by little (``docs/rendering.md``), and it
is found about once a pixel.
"""
import taichi as ti

from ..geometry import raycast
from ..geometry.shapes import SHAPES
from .drawables import COLLIDER_COLOUR, PARTICLE_COLOUR
from .raster import COLLIDER_ID, GROUND_ID, SKY_ID, TILE, bead

MESH_ID = COLLIDER_ID + (1 << 29)    # mesh colliders' triangle j has id MESH_ID + j
SHADOW_MAP = 1024
SMOOTH = 0.97      # triangles whose unit normals' product is above this are one surface


@ti.func
def _sky(d):
    s = 0.5 + 0.5 * d[1]
    return (1.0 - s) * ti.math.vec3(0.93, 0.95, 0.98) + s * ti.math.vec3(0.55, 0.70, 0.92)


@ti.func
def _facing(n, d):
    """n turned to face a ray along d."""
    return -n if n.dot(d) > 0.0 else n


@ti.func
def _joined(i, j):
    """Whether triangles of corner indices i and j share a corner."""
    joined = False
    for a, b in ti.static(ti.ndrange(3, 3)):
        if i[a] == j[b]:
            joined = True
    return joined


@ti.data_oriented
class Shading:
    """The Renderer's shading pass (module docstring): ``_shade`` writes ``image``."""

    @ti.kernel
    def _shade(self, x: ti.template(), time: ti.f32):
        """Each pixel's colour (module docstring), gamma 2 (square root) to bytes. What
        each sample sees (its id, ray and point) is read once and kept for the pixel."""
        ss = ti.static(self.ss)
        for r, c in self.image:
            at = [(r * ss + s // ss, c * ss + s % ss) for s in ti.static(range(ss * ss))]
            ids = [raycast.key_id(self.screen.depth[a]) for a in ti.static(at)]
            rays = [self.screen.ray(*a)[1] for a in ti.static(at)]
            points = [self._point(*a) for a in ti.static(at)]
            seen = self._one_surface(ids, rays, points, time)
            colour = ti.math.vec3(0.0)
            if seen:
                # one surface: lit once at the samples' mean point, seen along the middle ray
                o, ray = self.screen.ray(r * ss + 0.5 * (ss - 1), c * ss + 0.5 * (ss - 1))
                d = ray.normalized()
                p = ti.math.vec3(0.0)
                for s in ti.static(range(ss * ss)):
                    p += points[s]
                p *= 1.0 / (ss * ss)
                normal = ti.math.vec3(0.0)
                if seen == 2:
                    for s in ti.static(range(ss * ss)):
                        normal += _facing(self._facet(self._triangle(ids[s]), o, rays[s]),
                                          rays[s])
                colour = self._shaded(x, ids[0], o, d, p, points, seen == 2, normal, time)
            else:
                for s in range(ss * ss):
                    row, col = r * ss + s // ss, c * ss + s % ss
                    o, ray = self.screen.ray(row, col)
                    q = self._point(row, col)
                    colour += self._shaded(x, raycast.key_id(self.screen.depth[row, col]), o,
                                           ray.normalized(), q, [q], False,
                                           ti.math.vec3(0.0), time)
                colour *= 1.0 / (ss * ss)
            v = ti.sqrt(ti.math.clamp(colour, 0.0, 1.0))
            self.image[r, c] = ti.cast(v * 255.0 + 0.5, ti.u8)

    @ti.func
    def _triangle(self, k):
        """The index in the renderer's list of triangles of the one of id k, or -1."""
        j = -1
        if k < self.tri_count:
            j = k
        elif MESH_ID <= k < MESH_ID + ti.static(self.mesh_count):
            j = k - MESH_ID + self.tri_count
        return j

    @ti.func
    def _front(self, j, ray):
        """Whether triangle j shows its front to a ray along ``ray``."""
        return self.faces[j].dot(ray) < 0.0

    @ti.func
    def _one_surface(self, ids: ti.template(), rays: ti.template(), points: ti.template(),
                     time):
        """What the samples of a pixel (their ``ids``, ``rays`` and ``points``) see: 1 one
        primitive (a collider's normals within SMOOTH of each other: not across a box's
        edge), 2 triangles of one smooth surface (``_smooth``), 0 anything else."""
        k0 = ids[0]
        collider = COLLIDER_ID <= k0 < MESH_ID and not self._squared(k0)
        n0 = ti.math.vec3(0.0)
        seen = 1
        for s in ti.static(range(len(ids))):
            if seen and ids[s] != k0:
                seen = 2 if self._smooth(ids[s], k0, rays[s], rays[0]) else 0
            elif seen and collider:
                n = self._collider_normal(k0 - COLLIDER_ID, points[s], time)
                if ti.static(s == 0):
                    n0 = n
                elif n.dot(n0) <= SMOOTH:
                    seen = 0
        return seen

    @ti.func
    def _smooth(self, k, k0, ray, ray0):
        """Whether primitives k and k0, seen along ray and ray0, are one smooth surface:
        triangles of one cloth or mesh that share a corner, show the rays the same side
        and lie within SMOOTH of each other's plane."""
        smooth = False
        j, j0 = self._triangle(k), self._triangle(k0)
        if j >= 0 and j0 >= 0:
            smooth = (self.surface[j] == self.surface[j0]
                      and _joined(self.corners[j], self.corners[j0])
                      and self.faces[j].dot(self.faces[j0]) > SMOOTH
                      and self._front(j, ray) == self._front(j0, ray0))
        return smooth

    @ti.func
    def _shaded(self, x, k, o, d, p, points: ti.template(), several, normal, time):
        """The colour of what id k is where the unit ray o + t d meets it at p, the mean of
        ``points`` (a pixel's samples on it, or one of them): its colour there (the
        squares' averaged over the points), lit there with the shadow map read at each
        point (``several`` triangles: lit with ``normal``, the sum of theirs at the
        samples)."""
        colour = ti.math.vec3(0.0)
        if k == SKY_ID:
            colour = _sky(d)
        else:
            base, n = self._surface(x, k, o, d, p, several, time)
            if several:
                n = normal.normalized()
            n = _facing(n, d)
            lit = ti.max(n.dot(self._light()), 0.0)
            if self._squared(k):
                squares = ti.math.vec3(0.0)
                for s in ti.static(range(len(points))):
                    squares += self._square(points[s], n)
                base = self._fade(squares * ti.static(1.0 / len(points)), (p - o).norm())
            if ti.static(self.shadows):
                if lit > 0.0:
                    lit *= self._through(points, self._bias(lit)) * ti.static(1.0 / len(points))
            colour = self._shine(n, d, base, lit)
        return colour

    @ti.func
    def _point(self, row, col):
        """Where sample (row, col) hits (not the sky)."""
        o, ray = self.screen.ray(row, col)
        return o + raycast.key_t(self.screen.depth[row, col]) * ray

    @ti.func
    def _squared(self, k):
        """Whether id k is drawn with the ground's squares: the ground, a plane."""
        return k == GROUND_ID or (COLLIDER_ID <= k < MESH_ID and self._checkered(k - COLLIDER_ID))

    @ti.func
    def _surface(self, x, k, o, d, p, several, time):
        """(colour, unit normal) of surface id k (not the sky) at p, seen along the unit
        ray o + t d; the squared ones' colour is the caller's; no triangle's normal where
        ``several`` (the caller's)."""
        base = ti.math.vec3(COLLIDER_COLOUR)
        n = ti.math.vec3(0.0, 1.0, 0.0)
        j = self._triangle(k)
        if j >= 0:
            if not several:
                n = self._facet(j, o, d)
            base = self.palette[self.surface[j], 0 if self._front(j, d) else 1]
        elif k < COLLIDER_ID:
            n = (p - bead(x, self.sphere_ends, self.sphere_t, k - self.tri_count)).normalized()
            base = ti.math.vec3(PARTICLE_COLOUR)
        elif k != GROUND_ID:
            n = self._collider_normal(k - COLLIDER_ID, p, time)
        return base, n

    @ti.func
    def _facet(self, j, o, d):
        """The shading normal of triangle j where the ray o + t d meets its plane: its
        corners' normals interpolated there (the triangle's own where they cancel)."""
        i = self.corners[j]
        a, b, c = self.vertices[i[0]], self.vertices[i[1]], self.vertices[i[2]]
        hit = raycast.plane_hit(o, d, a, b, c)
        u, v = hit[1], hit[2]
        ns = ((1.0 - u - v) * self.normals[i[0]] + u * self.normals[i[1]]
              + v * self.normals[i[2]])
        return ns.normalized() if ns.norm() > 1e-20 else (b - a).cross(c - a).normalized()

    @ti.func
    def _shine(self, n, d, base, lit):
        """Colour ``base`` seen along d, its normal n facing the ray: hemisphere ambient,
        ``lit`` (the direct light reaching it: Lambert times the part the shadow map lets
        through) and a little specular."""
        half = (self._light() - d).normalized()
        spec = ti.max(half.dot(n), 0.0)
        for _ in ti.static(range(5)):
            spec = spec * spec
        hemi = 0.5 + 0.5 * n[1]
        return base * (0.22 + 0.18 * hemi + 0.65 * lit) + 0.12 * spec * ti.min(lit, 1.0)

    @ti.func
    def _light(self):
        return -self.light.vec(self.light.forward)

    @ti.func
    def _bias(self, cos_l):
        """How much nearer the light a blocker must be than a point that faces it at
        cos_l: more at grazing light (no self-shadowing acne)."""
        texel = 2.0 * ti.static(self.half) / SHADOW_MAP
        return texel * (1.5 + 2.0 * ti.sqrt(1.0 - cos_l * cos_l) / ti.max(cos_l, 0.2))

    @ti.func
    def _through(self, points: ti.template(), bias):
        """The sum of ``_unshadowed`` over ``points``, a pixel's samples on one surface: read
        once where all their 2 x 2 texels are off the map, or in one tile no nearer the
        light than the farthest of them (the same sum: each would find that)."""
        at = [self.shadow.project(q) for q in ti.static(points)]
        lo, hi = at[0], at[0]
        for i in ti.static(range(1, len(points))):
            lo, hi = ti.min(lo, at[i]), ti.max(hi, at[i])
        r0, c0 = ti.cast(ti.floor(lo[1] - 0.5), ti.i32), ti.cast(ti.floor(lo[0] - 0.5), ti.i32)
        r1, c1 = ti.cast(ti.floor(hi[1] - 0.5), ti.i32), ti.cast(ti.floor(hi[0] - 0.5), ti.i32)
        total = 0.0
        if (r1 < -1 or c1 < -1 or r0 >= SHADOW_MAP or c0 >= SHADOW_MAP
                or (r0 >= 0 and c0 >= 0 and r1 < SHADOW_MAP and c1 < SHADOW_MAP
                    and r0 // TILE == r1 // TILE and c0 // TILE == c1 // TILE
                    and self.shadow.nearest[r0 // TILE, c0 // TILE] >= hi[2] - bias)):
            total = 1.0 * ti.static(len(points))
        else:
            for i in ti.static(range(len(points))):
                total += self._unshadowed_at(at[i], bias)
        return total

    @ti.func
    def _unshadowed(self, p, bias):
        """``_unshadowed_at`` p's place in the shadow map."""
        return self._unshadowed_at(self.shadow.project(p), bias)

    @ti.func
    def _unshadowed_at(self, s, bias):
        """The fraction of the shadow map's 2 x 2 texels around p that do not block the
        light (``_open``), weighted bilinearly by p's position between their centres (a
        percentage-closer filter whose shadow edges are smooth ramps rather than
        texel-sized steps); s: p's (column, row, depth) in the shadow map."""
        gy, gx = s[1] - 0.5, s[0] - 0.5          # texel centres are at integer + 0.5
        ry, rx = ti.floor(gy), ti.floor(gx)
        fy, fx = gy - ry, gx - rx
        r0, c0 = ti.cast(ry, ti.i32), ti.cast(rx, ti.i32)
        depth = s[2] - bias
        visible = 1.0
        # none blocks where all four are off the map, or on it and no nearer than the
        # nearest of their tile
        if (-1 <= r0 < SHADOW_MAP and -1 <= c0 < SHADOW_MAP
                and not (r0 >= 0 and c0 >= 0
                         and self.shadow.nearest[r0 // TILE, c0 // TILE] >= depth)):
            visible = 0.0
            for j in range(4):
                dr, dc = j // 2, j % 2
                visible += (ti.select(dr, fy, 1.0 - fy) * ti.select(dc, fx, 1.0 - fx)
                            * self._open(r0 + dr, c0 + dc, depth))
        return visible

    @ti.func
    def _open(self, r, c, depth):
        """1 where shadow-map texel (r, c) lets light through to ``depth`` (off the map:
        nothing blocks), else 0."""
        out = 1.0
        if 0 <= r < SHADOW_MAP and 0 <= c < SHADOW_MAP:
            out = ti.select(self.shadow.depth[r, c] < depth, 0.0, 1.0)
        return out

    @ti.func
    def _square(self, p, n):
        """The colour of the ground's square at p (normal n): squares on the two axes
        least aligned with the normal."""
        an = ti.abs(n)
        skip = 0 if an[0] >= an[1] and an[0] >= an[2] else (1 if an[1] >= an[2] else 2)
        cell = 0
        for a in ti.static(range(3)):
            if a != skip:
                cell += ti.cast(ti.floor(p[a] * ti.static(1.0 / self.checker)), ti.i32)
        return ti.math.vec3(0.80) if cell % 2 == 0 else ti.math.vec3(0.62)

    @ti.func
    def _fade(self, base, t):
        """Squares' colour ``base`` at distance t, faded to their mean before they alias."""
        fade = 1.0 / (1.0 + t * ti.static(0.02 / self.checker))
        return fade * base + (1.0 - fade) * ti.math.vec3(0.71)

    @ti.func
    def _checkered(self, k):
        """True when collider k is drawn with the ground's squares."""
        checkered = False
        for g in ti.static(self.colliders.groups):
            if ti.static(SHAPES[g.shape].checkered):
                if g.first <= k < g.first + g.count:
                    checkered = True
        return checkered

    @ti.func
    def _collider_normal(self, k, p, time):
        """The shading normal of (analytic) collider k at surface point p."""
        n = ti.Vector([0.0, 1.0, 0.0], ti.f32)
        for g in ti.static(self.colliders.groups):
            if ti.static(not SHAPES[g.shape].meshed):
                if g.first <= k < g.first + g.count:
                    n = self.colliders.normal(g.shape, self.colliders.data[k], p, time)
        return n
