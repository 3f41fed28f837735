"""Off-screen renderer written in Taichi kernels (CPU or GPU, no display).

Every visible thing is ray-cast exactly: for each pixel a camera ray is tested against the
primitives whose screen bounding box covers it. Cloth triangles and particle spheres are
splatted over their boxes; the ground and colliders are tested at every pixel.

Visibility is race-free and deterministic: pass 1 writes the hit distance of every
primitive as int32 bits with ``atomic_min`` (positive floats order like their bits);
pass 2 lets every primitive whose distance equals the stored one ``atomic_min`` its id;
pass 3 shades each pixel from the winning id alone. The same scene gives the same image,
bit for bit, on every run.
"""
import math

import numpy as np
import taichi as ti

from . import runtime
from .errors import SceneError

SKY_ID = 2147483647
GROUND_ID = 2147483646

FRONT_COLOUR = (0.85, 0.28, 0.18)
BACK_COLOUR = (0.20, 0.42, 0.80)
PARTICLE_COLOUR = (0.95, 0.78, 0.25)
LIGHT_DIR = (0.45, 0.8, 0.4)


class Camera:
    """A perspective camera looking from ``eye`` at ``target``.

    Args:
        eye, target: (3,) metres. up: (3,) world up. fov: vertical field of view, degrees.
    """

    def __init__(self, eye, target, up=(0.0, 1.0, 0.0), fov=40.0):
        self.eye = np.asarray(eye, dtype=np.float64)
        self.target = np.asarray(target, dtype=np.float64)
        up = np.asarray(up, dtype=np.float64)
        fwd = self.target - self.eye
        if not np.all(np.isfinite(fwd)) or np.linalg.norm(fwd) == 0:
            raise SceneError(f"camera eye and target must differ (got eye={self.eye.tolist()}, "
                             f"target={self.target.tolist()})")
        if not 1.0 <= fov <= 170.0:
            raise SceneError(f"camera fov must be within [1, 170] degrees (got {fov})")
        self.fov = float(fov)
        self.forward = fwd / np.linalg.norm(fwd)
        right = np.cross(self.forward, up)
        if np.linalg.norm(right) < 1e-9:
            right = np.cross(self.forward, (1.0, 0.0, 0.0))
        self.right = right / np.linalg.norm(right)
        self.up = np.cross(self.right, self.forward)

    @classmethod
    def fit(cls, points, direction=(0.55, 0.45, 1.0), fov=40.0, margin=1.25):
        """A camera that sees all ``points`` (N,3) from ``direction``."""
        lo, hi = points.min(0), points.max(0)
        centre = 0.5 * (lo + hi)
        radius = max(0.5 * np.linalg.norm(hi - lo), 1e-3)
        d = np.asarray(direction, dtype=np.float64)
        dist = margin * radius / math.sin(math.radians(fov) / 2)
        return cls(centre + dist * d / np.linalg.norm(d), centre, fov=fov)

    @classmethod
    def from_config(cls, config, points):
        """None -> fit to points; a dict of Camera arguments; or a Camera."""
        if config is None:
            return cls.fit(points)
        if isinstance(config, Camera):
            return config
        if isinstance(config, dict):
            return cls(**config)
        raise SceneError(f"camera must be None, a dict or a tcloth.Camera (got {config!r})")


@ti.func
def _ray(eye, fwd, right, up, tan_half, aspect, col, row, w, h):
    sx = (2.0 * (col + 0.5) / w - 1.0) * tan_half * aspect
    sy = (1.0 - 2.0 * (row + 0.5) / h) * tan_half
    return (fwd + sx * right + sy * up).normalized()


@ti.func
def _project(p, eye, fwd, right, up, tan_half, aspect, w, h):
    """Pixel coordinates (col, row) and view depth z of point p."""
    d = p - eye
    z = d.dot(fwd)
    col = (d.dot(right) / (z * tan_half * aspect) + 1.0) * 0.5 * w - 0.5
    row = (1.0 - d.dot(up) / (z * tan_half)) * 0.5 * h - 0.5
    return ti.Vector([col, row, z])


@ti.func
def _hit_triangle(o, d, a, b, c):
    """Moller-Trumbore: (t, u, v) with t < 0 when the ray misses."""
    e1, e2 = b - a, c - a
    pv = d.cross(e2)
    det = e1.dot(pv)
    result = ti.Vector([-1.0, 0.0, 0.0], ti.f32)
    if abs(det) > 1e-12:
        inv = 1.0 / det
        tv = o - a
        u = tv.dot(pv) * inv
        qv = tv.cross(e1)
        v = d.dot(qv) * inv
        if u >= 0.0 and v >= 0.0 and u + v <= 1.0:
            result = ti.Vector([e2.dot(qv) * inv, u, v], ti.f32)
    return result


@ti.func
def _hit_sphere(o, d, centre, radius):
    """Nearest positive t of the ray on the sphere, or -1."""
    oc = o - centre
    b = oc.dot(d)
    disc = b * b - (oc.dot(oc) - radius * radius)
    t = -1.0
    if disc >= 0.0:
        s = ti.sqrt(disc)
        t = -b - s
        if t <= 0.0:
            t = -b + s
    return t


@ti.func
def _bits(t):
    return ti.bit_cast(ti.cast(t, ti.f32), ti.i32)


@ti.data_oriented
class Renderer:
    """Renders a Simulator's current state. Made once per (simulator, size) and reused.

    Args:
        sim: the Simulator. width, height: output pixels. camera: None (fit), dict or Camera.
        supersample: s x s samples per pixel, box-filtered (anti-aliasing).
        ground: height (y, m) of a checkered ground plane; None puts it just below the
            scene's lowest initial point; False draws none.
        particle_radius: radius (m) of drawn free/rope particles; None picks one.
    """

    def __init__(self, sim, width=640, height=480, camera=None, supersample=2, ground=None,
                 particle_radius=None):
        for name, value in (("width", width), ("height", height), ("supersample", supersample)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise SceneError(f"{name} must be a positive integer (got {value!r})")
        self.sim = sim
        self.width, self.height, self.ss = int(width), int(height), int(supersample)
        scene = sim.scene
        x0 = scene.positions
        self.camera = Camera.from_config(camera, x0)
        extent = float(np.linalg.norm(x0.max(0) - x0.min(0))) or 1.0
        if ground is None:
            ground = float(x0[:, 1].min()) - 0.3 * extent
        self.ground = ground
        self.checker = 10 ** math.floor(math.log10(extent / 2)) if extent > 0 else 0.1

        tris = [c.triangles for c in scene.cloths]
        self.tri_count = sum(len(t) for t in tris)
        in_cloth = np.zeros(scene.num_particles, dtype=bool)
        for c in scene.cloths:
            in_cloth[c.particles.ravel()] = True
        balls = np.flatnonzero(~in_cloth)
        sp = scene.springs
        line = sp["pairs"][~in_cloth[sp["pairs"][:, 0]] & ~in_cloth[sp["pairs"][:, 1]]]
        if particle_radius is None:
            rest = sp["rest_length"][~in_cloth[sp["pairs"][:, 0]]]
            particle_radius = 0.35 * float(np.median(rest)) if len(rest) else 0.02 * extent
        self.radius = float(particle_radius)
        # beads along free springs, spaced at most one radius apart at rest length
        beads = [np.stack([np.full(k, i), np.full(k, j), (np.arange(k) + 1) / (k + 1)], 1)
                 for (i, j), k in zip(line, np.ceil(
                     np.linalg.norm(x0[line[:, 0]] - x0[line[:, 1]], axis=1) / self.radius
                 ).astype(int) if len(line) else [])]
        spheres = np.concatenate([np.stack([balls, balls, np.zeros(len(balls))], 1)] + beads) \
            if len(balls) else np.zeros((0, 3))
        self.sphere_count = len(spheres)

        c = self.camera
        self.view = ti.Vector.field(16, ti.f32, shape=())
        self.view[None] = [*c.eye, *c.forward, *c.right, *c.up, math.tan(math.radians(c.fov) / 2),
                           self.width / self.height, float(self.ground or 0.0), self.checker]
        W, H = self.width * self.ss, self.height * self.ss
        self.depth = ti.field(ti.i32, shape=(H, W))
        self.ids = ti.field(ti.i32, shape=(H, W))
        self.colour = ti.Vector.field(3, ti.f32, shape=(H, W))
        self.image = ti.Vector.field(3, ti.u8, shape=(self.height, self.width))
        self.normals = ti.Vector.field(3, ti.f32, shape=scene.num_particles)
        self.tris = ti.Vector.field(3, ti.i32, shape=max(self.tri_count, 1))
        if self.tri_count:
            self.tris.from_numpy(np.concatenate(tris).astype(np.int32))
        self.sphere_ends = ti.Vector.field(2, ti.i32, shape=max(self.sphere_count, 1))
        self.sphere_t = ti.field(ti.f32, shape=max(self.sphere_count, 1))
        if self.sphere_count:
            self.sphere_ends.from_numpy(spheres[:, :2].astype(np.int32))
            self.sphere_t.from_numpy(spheres[:, 2].astype(np.float32))

    @ti.func
    def _view(self):
        """eye, forward, right, up, tan(fov/2), aspect, ground y, checker size."""
        v = self.view[None]
        return (ti.Vector([v[0], v[1], v[2]]), ti.Vector([v[3], v[4], v[5]]),
                ti.Vector([v[6], v[7], v[8]]), ti.Vector([v[9], v[10], v[11]]),
                v[12], v[13], v[14], v[15])

    def render(self):
        """(H,W,3) uint8 image of the simulator's current state."""
        self.sim._check()
        x = self.sim.state.x
        self._background(self.ground is not False)
        if self.tri_count:
            self._vertex_normals(x)
            self._splat_triangles(x, False)
            self._splat_triangles(x, True)
        if self.sphere_count:
            self._splat_spheres(x, False)
            self._splat_spheres(x, True)
        self._shade(x)
        self._resolve()
        return self.image.to_numpy()

    @ti.kernel
    def _background(self, has_ground: ti.template()):
        """Clear to sky; the ground plane y = ground_y is hit analytically."""
        h, w = self.depth.shape
        eye, fwd, right, up, tan_half, aspect, ground_y, _ = self._view()
        for r, c in ti.ndrange(h, w):
            self.depth[r, c] = SKY_ID
            self.ids[r, c] = SKY_ID
            if ti.static(has_ground):
                d = _ray(eye, fwd, right, up, tan_half, aspect, c, r, w, h)
                if d[1] < -1e-6:
                    t = (ground_y - eye[1]) / d[1]
                    if t > 0.0:
                        self.depth[r, c] = _bits(t)
                        self.ids[r, c] = GROUND_ID

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

    @ti.kernel
    def _splat_triangles(self, x: ti.template(), resolve_id: ti.template()):
        """Pass 1 (resolve_id=False): nearest distance. Pass 2: id of the nearest."""
        h, w = self.depth.shape
        eye, fwd, right, up, tan_half, aspect, _, _ = self._view()
        for k in range(self.tri_count):
            i = self.tris[k]
            a = ti.cast(x[i[0]], ti.f32)
            b = ti.cast(x[i[1]], ti.f32)
            c = ti.cast(x[i[2]], ti.f32)
            pa = _project(a, eye, fwd, right, up, tan_half, aspect, w, h)
            pb = _project(b, eye, fwd, right, up, tan_half, aspect, w, h)
            pc = _project(c, eye, fwd, right, up, tan_half, aspect, w, h)
            if pa[2] > 1e-3 and pb[2] > 1e-3 and pc[2] > 1e-3:
                c0 = ti.max(ti.cast(ti.floor(ti.min(pa[0], pb[0], pc[0])), ti.i32), 0)
                c1 = ti.min(ti.cast(ti.ceil(ti.max(pa[0], pb[0], pc[0])), ti.i32), w - 1)
                r0 = ti.max(ti.cast(ti.floor(ti.min(pa[1], pb[1], pc[1])), ti.i32), 0)
                r1 = ti.min(ti.cast(ti.ceil(ti.max(pa[1], pb[1], pc[1])), ti.i32), h - 1)
                for r in range(r0, r1 + 1):
                    for cc in range(c0, c1 + 1):
                        d = _ray(eye, fwd, right, up, tan_half, aspect, cc, r, w, h)
                        hit = _hit_triangle(eye, d, a, b, c)
                        if hit[0] > 0.0:
                            if ti.static(resolve_id):
                                if _bits(hit[0]) == self.depth[r, cc]:
                                    ti.atomic_min(self.ids[r, cc], k)
                            else:
                                ti.atomic_min(self.depth[r, cc], _bits(hit[0]))

    @ti.func
    def _sphere_centre(self, x, k):
        e = self.sphere_ends[k]
        s = self.sphere_t[k]
        return ti.cast((1.0 - s) * x[e[0]] + s * x[e[1]], ti.f32)

    @ti.kernel
    def _splat_spheres(self, x: ti.template(), resolve_id: ti.template()):
        """Particles and beads along free springs as spheres; ids follow the triangles'."""
        h, w = self.depth.shape
        eye, fwd, right, up, tan_half, aspect, _, _ = self._view()
        radius = self.radius
        for k in range(self.sphere_count):
            centre = self._sphere_centre(x, k)
            pc = _project(centre, eye, fwd, right, up, tan_half, aspect, w, h)
            if pc[2] > radius + 1e-3:
                reach = radius / (pc[2] - radius) / (tan_half * 2.0) * h + 2.0
                c0 = ti.max(ti.cast(ti.floor(pc[0] - reach), ti.i32), 0)
                c1 = ti.min(ti.cast(ti.ceil(pc[0] + reach), ti.i32), w - 1)
                r0 = ti.max(ti.cast(ti.floor(pc[1] - reach), ti.i32), 0)
                r1 = ti.min(ti.cast(ti.ceil(pc[1] + reach), ti.i32), h - 1)
                for r in range(r0, r1 + 1):
                    for cc in range(c0, c1 + 1):
                        d = _ray(eye, fwd, right, up, tan_half, aspect, cc, r, w, h)
                        t = _hit_sphere(eye, d, centre, radius)
                        if t > 0.0:
                            if ti.static(resolve_id):
                                if _bits(t) == self.depth[r, cc]:
                                    ti.atomic_min(self.ids[r, cc], self.tri_count + k)
                            else:
                                ti.atomic_min(self.depth[r, cc], _bits(t))

    @ti.kernel
    def _shade(self, x: ti.template()):
        """Lambert + ambient + a little specular; cloth front and back in two colours."""
        h, w = self.depth.shape
        eye, fwd, right, up, tan_half, aspect, _, checker = self._view()
        light = ti.math.vec3(LIGHT_DIR).normalized()
        for r, c in ti.ndrange(h, w):
            d = _ray(eye, fwd, right, up, tan_half, aspect, c, r, w, h)
            k = self.ids[r, c]
            t = ti.bit_cast(self.depth[r, c], ti.f32)
            base = ti.math.vec3(0.0)
            n = ti.math.vec3(0.0, 1.0, 0.0)
            lit = True
            if k == SKY_ID:
                s = 0.5 + 0.5 * d[1]
                base = (1.0 - s) * ti.math.vec3(0.93, 0.95, 0.98) + s * ti.math.vec3(0.55, 0.70, 0.92)
                lit = False
            elif k == GROUND_ID:
                p = eye + t * d
                cell = ti.cast(ti.floor(p[0] / checker) + ti.floor(p[2] / checker), ti.i32)
                base = ti.math.vec3(0.78) if cell % 2 == 0 else ti.math.vec3(0.66)
                fade = ti.exp(-0.02 * t / checker)
                base = fade * base + (1.0 - fade) * ti.math.vec3(0.9, 0.92, 0.95)
            elif k < self.tri_count:
                i = self.tris[k]
                a = ti.cast(x[i[0]], ti.f32)
                b = ti.cast(x[i[1]], ti.f32)
                cv = ti.cast(x[i[2]], ti.f32)
                hit = _hit_triangle(eye, d, a, b, cv)
                u, v = hit[1], hit[2]
                ns = ((1.0 - u - v) * self.normals[i[0]] + u * self.normals[i[1]]
                      + v * self.normals[i[2]])
                ng = (b - a).cross(cv - a)
                front = ng.dot(d) < 0.0
                base = ti.math.vec3(FRONT_COLOUR) if front else ti.math.vec3(BACK_COLOUR)
                n = ns.normalized() if ns.norm() > 1e-20 else ng.normalized()
                if not front:
                    n = -n
            else:
                centre = self._sphere_centre(x, k - self.tri_count)
                n = (eye + t * d - centre).normalized()
                base = ti.math.vec3(PARTICLE_COLOUR)
            if lit:
                diffuse = ti.max(n.dot(light), 0.0)
                hemi = 0.5 + 0.5 * n[1]
                spec = ti.max((light - d).normalized().dot(n), 0.0)
                for _ in ti.static(range(5)):
                    spec = spec * spec
                base = base * (0.25 + 0.15 * hemi + 0.7 * diffuse) + 0.15 * spec
            self.colour[r, c] = base

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


def render(sim, width=640, height=480, camera=None, supersample=2, **options):
    """(H,W,3) uint8 image of ``sim``'s current state; no display needed.

    The Renderer is kept on the simulator and reused while the arguments stay the same.
    Options: ground, particle_radius (see Renderer).
    """
    key = (width, height, repr(camera), supersample, repr(sorted(options.items())))
    cached = getattr(sim, "_renderer", None)
    if cached is None or cached[0] != key or cached[2] != runtime.generation():
        sim._renderer = (key, Renderer(sim, width, height, camera, supersample, **options),
                         runtime.generation())
    return sim._renderer[1].render()
