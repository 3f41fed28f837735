"""Off-screen renderer written in Taichi kernels (CPU or GPU, no display).

Everything visible is ray-cast exactly. Cloth triangles and particle spheres are splatted:
each primitive tests the camera rays of the pixels its projected bounding box covers.
The ground and the colliders (every shape of ``shapes.SHAPES``, through its ray hit) are
tested at every pixel.

Visibility is race-free and deterministic: every hit is one int64 key (``raycast.py``)
combined with ``atomic_min``: the nearest hit wins, ties go to the smaller id, whatever
the order of the threads. The shading pass reads the winning id alone. The same scene
gives the same image, bit for bit, every run.

Shadows come from a shadow map: the same splatting seen from the light (orthographic).
"""
import math
import weakref

import numpy as np
import taichi as ti

from ..geometry import raycast
from .. import runtime
from .camera import Camera
from .drawables import DrawnCloth, cloth_palette, particle_spheres
from ..errors import SceneError
from .framing import ground_and_checker
from ..geometry.shapes import SHAPES

SKY_ID = 2147483647
SKY_KEY = (2147483647 << 32) | SKY_ID
GROUND_ID = 2147483646
COLLIDER_ID = 1 << 30          # collider c has id COLLIDER_ID + c

PARTICLE_COLOUR = (0.95, 0.78, 0.25)
COLLIDER_COLOUR = (0.50, 0.58, 0.66)
LIGHT_DIR = (0.35, 0.85, 0.4)
SHADOW_MAP = 1024


@ti.data_oriented
class Renderer:
    """Renders a Simulator's current state. Made once per (simulator, size) and reused.

    Args:
        sim: the Simulator. width, height: output pixels. camera: None (fit), dict or Camera.
        supersample: s x s samples per pixel, box-filtered (anti-aliasing).
        ground: height (y, m) of a checkered ground plane; False draws none; None
            (default) draws none where the scene has plane colliders (drawn instead) or
            something that can fall without end, else puts it just below the lowest
            point anything can reach (``framing.lowest_reach``: a pinned cloth hanging
            down, the colliders).
        particle_radius: radius (m) of drawn free and rope particles; None picks one.
        shadows: cast shadows from the light (a shadow map); default True.
        cloth_colours: None, or one (front RGB, back RGB) pair per cloth, values in [0, 1].
    """

    def __init__(self, sim, width=640, height=480, camera=None, supersample=2, ground=None,
                 particle_radius=None, shadows=True, cloth_colours=None):
        for name, value in (("width", width), ("height", height), ("supersample", supersample)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise SceneError(f"{name} must be a positive integer (got {value!r})")
        self.sim = sim
        self.width, self.height, self.ss = int(width), int(height), int(supersample)
        scene, model = sim.scene, sim.model
        x0 = scene.positions
        self.camera = Camera.from_config(camera, x0)
        lo, hi = x0.min(0), x0.max(0)
        extent = float(np.linalg.norm(hi - lo)) or 1.0
        self.ground, self.checker = ground_and_checker(scene, ground, extent)
        self.colliders = model.colliders
        self.shadows = bool(shadows)

        tris = [c.triangles for c in scene.cloths]
        self.tri_count = sum(len(t) for t in tris)
        palette = cloth_palette(cloth_colours, len(tris))
        spheres, self.radius = particle_spheres(scene, particle_radius, extent)
        self.sphere_count = len(spheres)

        c = self.camera
        light = np.asarray(LIGHT_DIR) / np.linalg.norm(LIGHT_DIR)
        lu = np.cross(light, (0.0, 0.0, 1.0))
        lu /= np.linalg.norm(lu)
        lw = np.cross(light, lu)
        centre = 0.5 * (lo + hi)
        # view: camera (eye, forward, right, up, tan(fov/2), aspect, ground y, checker),
        # then the light's orthographic frame (origin, -L direction, u, w, half size)
        half = 1.5 * extent
        # compile-time constants: a Renderer is made per camera, so its kernels bake them in
        self.view = tuple(float(v) for v in np.array(
            [*c.eye, *c.forward, *c.right, *c.up, math.tan(math.radians(c.fov) / 2),
             self.width / self.height, float(self.ground or 0.0), self.checker,
             *(centre + 4 * extent * light), *(-light), *lu, *lw, half], dtype=np.float32))
        self.time = ti.field(ti.f32, shape=())
        self._static_ready = False
        W, H = self.width * self.ss, self.height * self.ss
        self.depth = ti.field(ti.i64, shape=(H, W))
        shadow_shape = (SHADOW_MAP, SHADOW_MAP) if self.shadows else (1, 1)
        self.shadow = ti.field(ti.i64, shape=shadow_shape)
        # colliders that do not move cast the same shadow every frame: computed once
        self.moving = any(np.any(c["velocity"] != 0) for c in scene.colliders)
        self.shadow_static = None if self.moving else ti.field(ti.i64, shape=shadow_shape)
        self.colour = ti.Vector.field(3, ti.f32, shape=(H, W))
        self.image = ti.Vector.field(3, ti.u8, shape=(self.height, self.width))
        self.normals = ti.Vector.field(3, ti.f32, shape=scene.num_particles)
        # the cloth's triangles and where they are drawn (out of the colliders they rest on)
        self.cloth = DrawnCloth(self.colliders, np.concatenate(tris) if self.tri_count
                                else np.zeros((0, 3), np.int32), scene.num_particles)
        self.tris = self.cloth.tris
        self.tri_cloth = ti.field(ti.i32, shape=max(self.tri_count, 1))
        self.palette = ti.Vector.field(3, ti.f32, shape=(max(len(tris), 1), 2))
        if self.tri_count:
            self.tri_cloth.from_numpy(np.concatenate(
                [np.full(len(t), k, dtype=np.int32) for k, t in enumerate(tris)]))
            self.palette.from_numpy(palette.astype(np.float32))
        self.sphere_ends = ti.Vector.field(2, ti.i32, shape=max(self.sphere_count, 1))
        self.sphere_t = ti.field(ti.f32, shape=max(self.sphere_count, 1))
        if self.sphere_count:
            self.sphere_ends.from_numpy(spheres[:, :2].astype(np.int32))
            self.sphere_t.from_numpy(spheres[:, 2].astype(np.float32))

    # -- per frame ---------------------------------------------------------------------------
    def render(self):
        """(H,W,3) uint8 image of the simulator's current state."""
        self.sim._check()
        x = self.sim.state.x
        self.time[None] = self.sim.time
        cloth = self.cloth.x
        if self.tri_count:
            self.cloth.update(x, self.sim.time)
            self._vertex_normals(cloth)
        targets = [(self.depth, True)] + ([(self.shadow, False)] if self.shadows else [])
        for depth, camera in targets[::-1]:
            if camera or self.moving:
                self._analytic(depth, camera, self.ground is not False and camera)
            else:
                if self._static_ready is False:
                    self._analytic(self.shadow_static, False, False)
                    self._static_ready = True
                self.shadow.copy_from(self.shadow_static)
            if self.tri_count:
                self._splat_triangles(cloth, depth, camera)
            if self.sphere_count:
                self._splat_spheres(x, depth, camera)
        self._shade(x, cloth)
        self._resolve()
        return self.image.to_numpy()

    def ids(self):
        """(H*s, W*s) int array: the id seen at each sample of the last render (cloth
        triangles 0.., then spheres; colliders from 2**30; ground and sky the largest)."""
        return (self.depth.to_numpy() & 0x7FFFFFFF).astype(np.int32)

    # -- rays of the camera (perspective) and of the light (orthographic) --------------------
    @ti.func
    def _vec(self, k: ti.template()):
        return ti.Vector([ti.static(self.view[k]), ti.static(self.view[k + 1]),
                          ti.static(self.view[k + 2])])

    @ti.func
    def _ray(self, camera: ti.template(), row, col, h, w):
        """Origin and unit direction of the ray through pixel (row, col) of an h x w target."""
        o = ti.Vector([0.0, 0.0, 0.0])
        d = ti.Vector([0.0, 0.0, 0.0])
        if ti.static(camera):
            tan_half, aspect = ti.static(self.view[12]), ti.static(self.view[13])
            sx = (2.0 * (col + 0.5) / w - 1.0) * tan_half * aspect
            sy = (1.0 - 2.0 * (row + 0.5) / h) * tan_half
            o = self._vec(0)
            d = (self._vec(3) + sx * self._vec(6) + sy * self._vec(9)).normalized()
        else:
            half = ti.static(self.view[28])
            o = (self._vec(16) + (2.0 * (col + 0.5) / w - 1.0) * half * self._vec(22)
                 + (1.0 - 2.0 * (row + 0.5) / h) * half * self._vec(25))
            d = self._vec(19)
        return o, d

    @ti.func
    def _project(self, camera: ti.template(), p, h, w):
        """(col, row, depth) of point p on an h x w target; depth <= 0 is behind."""
        result = ti.Vector([0.0, 0.0, 0.0])
        if ti.static(camera):
            d = p - self._vec(0)
            z = d.dot(self._vec(3))
            tan_half, aspect = ti.static(self.view[12]), ti.static(self.view[13])
            result = ti.Vector([(d.dot(self._vec(6)) / (z * tan_half * aspect) + 1.0) * 0.5 * w - 0.5,
                                (1.0 - d.dot(self._vec(9)) / (z * tan_half)) * 0.5 * h - 0.5, z])
        else:
            d = p - self._vec(16)
            half = ti.static(self.view[28])
            result = ti.Vector([(d.dot(self._vec(22)) / half + 1.0) * 0.5 * w - 0.5,
                                (1.0 - d.dot(self._vec(25)) / half) * 0.5 * h - 0.5,
                                d.dot(self._vec(19))])
        return result

    # -- passes ------------------------------------------------------------------------------
    @ti.kernel
    def _analytic(self, depth: ti.template(), camera: ti.template(), has_ground: ti.template()):
        """Clear to sky, then the ground plane and the colliders, hit analytically where
        they are (cloth resting on them is drawn out of them: ``DrawnCloth``)."""
        h, w = depth.shape
        time = self.time[None]
        for r, c in ti.ndrange(h, w):
            o, d = self._ray(camera, r, c, h, w)
            best, best_id = 1e30, SKY_ID
            if ti.static(has_ground):
                if d[1] < -1e-6:
                    t = (ti.static(self.view[14]) - o[1]) / d[1]
                    if t > 0.0:
                        best, best_id = t, GROUND_ID
            for g in ti.static(self.colliders.groups):
                # checkered shapes (planes) receive shadows but cast none worth a test
                if ti.static(camera or not SHAPES[g.shape].checkered):
                    for k in range(g.first, g.first + g.count):
                        t = ti.cast(self.colliders.ray_hit(g.shape, self.colliders.data[k],
                                                           o, d, time), ti.f32)
                        if 0.0 < t < best:
                            best, best_id = t, COLLIDER_ID + k
            key = ti.i64(SKY_KEY)
            if best_id != SKY_ID:
                key = raycast.key(best, best_id)
            depth[r, c] = key

    @ti.kernel
    def _vertex_normals(self, x: ti.template()):
        """Area-weighted vertex normals of the cloth triangles."""
        for p in self.normals:
            self.normals[p] = ti.Vector.zero(ti.f32, 3)
        for k in range(self.tri_count):
            a, b, c = self.tris[k][0], self.tris[k][1], self.tris[k][2]
            n = ti.cast((x[b] - x[a]).cross(x[c] - x[a]), ti.f32)
            self.normals[a] += n
            self.normals[b] += n
            self.normals[c] += n

    @ti.func
    def _splat(self, depth: ti.template(), camera: ti.template(), sphere: ti.template(), h, w,
               lo, hi, prim_id, a, b, c, radius):
        """Test the rays of the pixels in [lo, hi] (col, row) against one triangle (a, b, c)
        or one sphere (centre a, radius)."""
        for r in range(ti.max(ti.cast(ti.floor(lo[1]), ti.i32), 0),
                       ti.min(ti.cast(ti.ceil(hi[1]), ti.i32), h - 1) + 1):
            for col in range(ti.max(ti.cast(ti.floor(lo[0]), ti.i32), 0),
                             ti.min(ti.cast(ti.ceil(hi[0]), ti.i32), w - 1) + 1):
                o, d = self._ray(camera, r, col, h, w)
                hit = 0.0
                if ti.static(sphere):
                    hit = raycast.hit_sphere(o, d, a, radius)
                else:
                    hit = raycast.hit_triangle(o, d, a, b, c)[0]
                if hit > 0.0:
                    ti.atomic_min(depth[r, col], raycast.key(hit, prim_id))

    @ti.kernel
    def _splat_triangles(self, x: ti.template(), depth: ti.template(), camera: ti.template()):
        """Cloth triangles; id k for triangle k."""
        h, w = depth.shape
        for k in range(self.tri_count):
            i = self.tris[k]
            a = ti.cast(x[i[0]], ti.f32)
            b = ti.cast(x[i[1]], ti.f32)
            c = ti.cast(x[i[2]], ti.f32)
            pa = self._project(camera, a, h, w)
            pb = self._project(camera, b, h, w)
            pc = self._project(camera, c, h, w)
            if pa[2] > 1e-3 and pb[2] > 1e-3 and pc[2] > 1e-3:
                self._splat(depth, camera, False, h, w, ti.min(pa, pb, pc),
                            ti.max(pa, pb, pc), k, a, b, c, 0.0)

    @ti.func
    def _sphere_centre(self, x, k):
        e = self.sphere_ends[k]
        s = self.sphere_t[k]
        return ti.cast((1.0 - s) * x[e[0]] + s * x[e[1]], ti.f32)

    @ti.kernel
    def _splat_spheres(self, x: ti.template(), depth: ti.template(), camera: ti.template()):
        """Free particles and beads along free springs; ids follow the triangles'."""
        h, w = depth.shape
        radius = ti.static(self.radius)
        for k in range(self.sphere_count):
            centre = self._sphere_centre(x, k)
            pc = self._project(camera, centre, h, w)
            reach = 2.0 + radius / ti.static(self.view[28]) * 0.5 * h
            visible = True
            if ti.static(camera):
                reach = 2.0 + radius / (pc[2] - radius) / (ti.static(self.view[12]) * 2.0) * h
                visible = pc[2] > radius + 1e-3
            if visible:
                self._splat(depth, camera, True, h, w, pc - reach, pc + reach,
                            self.tri_count + k, centre, centre, centre, radius)

    @ti.func
    def _lit(self, p, n):
        """Direct light reaching point p with normal n: Lambert times the fraction of the
        shadow map's 2 x 2 texels around p that do not block it, weighted bilinearly by
        p's position between their centres (a percentage-closer filter whose shadow edges
        are smooth ramps rather than texel-sized steps), with a bias that grows at grazing
        light (no self-shadowing acne)."""
        light = -self._vec(19)
        cos_l = n.dot(light)
        lit = ti.max(cos_l, 0.0)
        if ti.static(self.shadows) and lit > 0.0:
            s = self._project(False, p, SHADOW_MAP, SHADOW_MAP)
            texel = 2.0 * ti.static(self.view[28]) / SHADOW_MAP
            bias = texel * (1.5 + 2.0 * ti.sqrt(1.0 - cos_l * cos_l) / ti.max(cos_l, 0.2))
            # texel centres are at integer + 0.5
            fy, fx = s[1] - 0.5 - ti.floor(s[1] - 0.5), s[0] - 0.5 - ti.floor(s[0] - 0.5)
            r0 = ti.cast(ti.floor(s[1] - 0.5), ti.i32)
            c0 = ti.cast(ti.floor(s[0] - 0.5), ti.i32)
            visible = 0.0
            for dr, dc in ti.static(ti.ndrange(2, 2)):
                r, c = r0 + dr, c0 + dc
                blocked = False
                if 0 <= r < SHADOW_MAP and 0 <= c < SHADOW_MAP:
                    blocker = self.shadow[r, c]
                    depth = raycast.key_t(blocker)
                    blocked = blocker != ti.i64(SKY_KEY) and depth < s[2] - bias
                if not blocked:
                    visible += (fy if dr else 1.0 - fy) * (fx if dc else 1.0 - fx)
            lit *= visible
        return lit

    @ti.kernel
    def _shade(self, x: ti.template(), cloth: ti.template()):
        """Lambert + hemisphere ambient + a little specular, with shadows; cloth (drawn at
        ``cloth``) front and back in two colours, checkered ground and planes; particle
        spheres at ``x``."""
        h, w = self.depth.shape
        time = self.time[None]
        checker = ti.static(self.view[15])
        for r, c in ti.ndrange(h, w):
            o, d = self._ray(True, r, c, h, w)
            k = raycast.key_id(self.depth[r, c])
            t = raycast.key_t(self.depth[r, c])
            p = o + t * d
            base = ti.math.vec3(0.0)
            n = ti.math.vec3(0.0, 1.0, 0.0)
            if k == SKY_ID:
                s = 0.5 + 0.5 * d[1]
                base = (1.0 - s) * ti.math.vec3(0.93, 0.95, 0.98) + s * ti.math.vec3(0.55, 0.70, 0.92)
            elif k == GROUND_ID or (k >= COLLIDER_ID and self._checkered(k - COLLIDER_ID)):
                if k != GROUND_ID:
                    n = self._collider_normal(k - COLLIDER_ID, p, time)
                # squares on the two axes least aligned with the normal
                an = ti.abs(n)
                skip = 0 if an[0] >= an[1] and an[0] >= an[2] else (1 if an[1] >= an[2] else 2)
                cell = 0
                for a in ti.static(range(3)):
                    if a != skip:
                        cell += ti.cast(ti.floor(p[a] / checker), ti.i32)
                base = ti.math.vec3(0.80) if cell % 2 == 0 else ti.math.vec3(0.62)
                # fade distant squares to their mean before they alias
                fade = 1.0 / (1.0 + 0.02 * t / checker)
                base = fade * base + (1.0 - fade) * ti.math.vec3(0.71)
            elif k >= COLLIDER_ID:
                base = ti.math.vec3(COLLIDER_COLOUR)
                n = self._collider_normal(k - COLLIDER_ID, p, time)
            elif k < self.tri_count:
                i = self.tris[k]
                a, b, cv = cloth[i[0]], cloth[i[1]], cloth[i[2]]
                hit = raycast.hit_triangle(o, d, a, b, cv)
                u, v = hit[1], hit[2]
                ns = ((1.0 - u - v) * self.normals[i[0]] + u * self.normals[i[1]]
                      + v * self.normals[i[2]])
                ng = (b - a).cross(cv - a)
                front = ng.dot(d) < 0.0
                base = self.palette[self.tri_cloth[k], 0 if front else 1]
                n = ns.normalized() if ns.norm() > 1e-20 else ng.normalized()
                if not front:
                    n = -n
            else:
                n = (p - self._sphere_centre(x, k - self.tri_count)).normalized()
                base = ti.math.vec3(PARTICLE_COLOUR)
            if k != SKY_ID:
                if n.dot(d) > 0.0:
                    n = -n
                lit = self._lit(p, n)
                half = (-self._vec(19) - d).normalized()
                spec = ti.max(half.dot(n), 0.0)
                for _ in ti.static(range(5)):
                    spec = spec * spec
                hemi = 0.5 + 0.5 * n[1]
                base = base * (0.22 + 0.18 * hemi + 0.65 * lit) + 0.12 * spec * ti.min(lit, 1.0)
            self.colour[r, c] = ti.cast(base, ti.f32)

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
        """The shading normal of collider k at surface point p."""
        n = ti.Vector([0.0, 1.0, 0.0], ti.f32)
        for g in ti.static(self.colliders.groups):
            if g.first <= k < g.first + g.count:
                n = self.colliders.normal(g.shape, self.colliders.data[k], p, time)
        return n

    @ti.kernel
    def _resolve(self):
        """Box-filter the supersamples; gamma 2 (square root) to bytes."""
        ss = self.depth.shape[0] // self.image.shape[0]
        for r, c in ti.ndrange(self.image.shape[0], self.image.shape[1]):
            acc = ti.math.vec3(0.0)
            for dr, dc in ti.ndrange(ss, ss):
                acc += self.colour[r * ss + dr, c * ss + dc]
            v = ti.sqrt(ti.math.clamp(acc / (ss * ss), 0.0, 1.0))
            self.image[r, c] = ti.cast(v * 255.0 + 0.5, ti.u8)


# each simulator's last Renderer and the arguments it was made for (``renderer_for``)
_RENDERERS = weakref.WeakKeyDictionary()


def render(sim, width=640, height=480, camera=None, supersample=2, **options):
    """(H,W,3) uint8 image of ``sim``'s current state; no display needed.

    The Renderer is kept on the simulator and reused while the arguments stay the same.
    Options: ground, particle_radius, shadows (see Renderer).
    """
    return renderer_for(sim, width, height, camera, supersample, **options).render()


def renderer_for(sim, width=640, height=480, camera=None, supersample=2, **options):
    """The simulator's Renderer for these arguments, made on first use and then reused
    (a new Renderer compiles its kernels again)."""
    key = (width, height, repr(camera), supersample, repr(sorted(options.items())),
           runtime.generation())
    cached = _RENDERERS.get(sim)
    if cached is None or cached[0] != key:
        cached = _RENDERERS[sim] = (key, Renderer(sim, width, height, camera, supersample,
                                                  **options))
    return cached[1]
