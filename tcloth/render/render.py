"""Off-screen renderer written in Taichi kernels (CPU or GPU, no display).

A frame is drawn into two depth targets (``raster.py``): the camera's, supersample x
supersample samples a pixel, and the light's shadow map (orthographic). Triangles, the
cloth's and the mesh colliders', are rasterised; spheres (free particles, beads along
ropes) and the other colliders are ray-cast within their bounding spheres' projections.
What never moves (the ground, colliders without velocity, mesh colliders that neither
move, turn nor deform) is drawn once, at the first frame, into both targets, and every
frame starts from it: a frame costs what moves and the pixels, not the static scene.

Visibility is race-free and deterministic: every hit is one int64 key (``raycast.py``)
combined with ``atomic_min``: the nearest hit wins, ties go to the smaller id, whatever
the order of the threads. The shading pass reads the winning id and depth at each sample
and box-filters the samples of each pixel into it. The same scene gives the same image,
bit for bit, every run.
"""
from typing import TYPE_CHECKING, Any, Optional

import contextlib
import math
import time as clock
import weakref

import numpy as np
import taichi as ti

from .. import runtime
from .camera import Camera
from .drawables import (COLLIDER_COLOUR, DrawnCloth, cloth_palette, collider_moves,
                        particle_spheres)
from ..errors import SceneError
from .framing import ground_and_checker
from .raster import Target, View
from .shading import MESH_ID, SHADOW_MAP, Shading
from ..geometry.shapes import shape_of

if TYPE_CHECKING:
    from ..sim.simulator import Simulator

LIGHT_DIR = (0.35, 0.85, 0.4)
UNBOUNDED = 1e9      # m: the bounding radius of a plane


def bounding_radius(collider):
    """The radius (m) of a sphere about an analytic collider's centre that holds it."""
    shape = shape_of(collider)
    if shape.checkered:
        return UNBOUNDED
    vertices = shape.mesh(collider, 1.0, 1.0)[0]
    return float(np.linalg.norm(vertices, axis=1).max())


@ti.data_oriented
class Renderer(Shading):
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

    ``timings``: None, or a dict to which ``render`` adds the seconds of each of its
    passes (``tools/bench_render.py``).
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
        self.timings = None

        tris = [c.triangles for c in scene.cloths]
        self.tri_count = sum(len(t) for t in tris)
        palette = cloth_palette(cloth_colours, len(tris))
        spheres, self.radius = particle_spheres(scene, particle_radius, extent)
        self.sphere_count = len(spheres)

        c = self.camera
        tan_half = math.tan(math.radians(c.fov) / 2)
        self.screen = Target(View(c.eye, c.forward, c.right, c.up, tan_half * width / height,
                                  tan_half, True, self.height * self.ss, self.width * self.ss),
                             ids=True, ground=self.ground)
        # the light's orthographic frame: from far along the light, across the scene
        light = np.asarray(LIGHT_DIR) / np.linalg.norm(LIGHT_DIR)
        lu = np.cross(light, (0.0, 0.0, 1.0))
        lu /= np.linalg.norm(lu)
        self.half = float(np.float32(1.5 * extent))
        self.light = View(0.5 * (lo + hi) + 4 * extent * light, -light, lu, np.cross(light, lu),
                          self.half, self.half, False, SHADOW_MAP, SHADOW_MAP)
        self.shadow = Target(self.light, ids=False) if self.shadows else None
        self.image = ti.Vector.field(3, ti.u8, shape=(self.height, self.width))
        # the cloth's triangles and where they are drawn (out of the colliders they rest on)
        cloth_tris = np.concatenate(tris) if self.tri_count else np.zeros((0, 3), np.int32)
        self.cloth = DrawnCloth(self.colliders, cloth_tris, scene.num_particles)
        self.particles = scene.num_particles
        mesh_tris, mesh_rows, mesh_moving = self._colliders(
            [scene.colliders[i] for i in self.colliders.rows])
        self._triangles(cloth_tris, [np.full(len(t), k) for k, t in enumerate(tris)],
                        np.concatenate([palette, [(COLLIDER_COLOUR, COLLIDER_COLOUR)]]),
                        mesh_tris, mesh_rows, mesh_moving)
        self.sphere_ends = ti.Vector.field(2, ti.i32, shape=max(self.sphere_count, 1))
        self.sphere_t = ti.field(ti.f32, shape=max(self.sphere_count, 1))
        if self.sphere_count:
            self.sphere_ends.from_numpy(spheres[:, :2].astype(np.int32))
            self.sphere_t.from_numpy(spheres[:, 2].astype(np.float32))
        self._static_ready = False

    def _colliders(self, rows):
        """Which of the collider table's ``rows`` (scene dicts) move; (the mesh colliders'
        triangles (corners: the mesh store's vertices), the static ones' first; the row of
        each store vertex, whether it moves)."""
        moving = [collider_moves(c) for c in rows]
        self.row_moving = ti.field(ti.i32, shape=max(len(rows), 1))
        if rows:
            self.row_moving.from_numpy(np.array(moving, dtype=np.int32))
        flying = [k for k, c in enumerate(rows) if moving[k] and c["kind"] != "mesh"]
        self.flying = len(flying)
        self.flying_rows = ti.field(ti.i32, shape=max(self.flying, 1))
        self.flying_radii = ti.field(ti.f32, shape=max(self.flying, 1))
        if flying:
            self.flying_rows.from_numpy(np.array(flying, dtype=np.int32))
            self.flying_radii.from_numpy(np.array([bounding_radius(rows[k]) for k in flying],
                                                  dtype=np.float32))
        store = self.colliders.meshes
        records = store.records if store is not None else []
        lists = ([], [])
        vertex_row, vertex_moving = [], []
        for m, r in enumerate(records):
            k = self.colliders.mesh_rows[m]
            lists[moving[k]].append(r["tris"] + r["vert_first"])
            vertex_row.append(np.full(len(r["v"]), k))
            vertex_moving.append(np.full(len(r["v"]), moving[k]))
        self.mesh_static = sum(len(t) for t in lists[0])
        return ([np.zeros((0, 3), np.int64)] + lists[0] + lists[1],
                [np.zeros(0, np.int64)] + vertex_row, [np.zeros(0, np.int64)] + vertex_moving)

    def _triangles(self, cloth_tris, cloth_of, palette, mesh_tris, mesh_rows, mesh_moving):
        """Every triangle drawn, in one list: the cloth's (``tri_count``; corners: the
        particles), then the mesh colliders' (``mesh_count``; corners: the mesh store's
        vertices, after the particles); where they are drawn (``vertices``, ``normals``),
        their unit normals (``faces``) and colours (``palette`` rows, ``surface``: the
        cloth's, or the colliders' last)."""
        mesh_tris = np.concatenate(mesh_tris) + self.particles
        self.mesh_count = len(mesh_tris)
        self.mesh_vertices = sum(len(v) for v in mesh_rows)
        count = self.tri_count + self.mesh_count
        self.corners = ti.Vector.field(3, ti.i32, shape=max(count, 1))
        # the cloth's triangles drawn: the first ``cloth_live`` (``_follow_surface``)
        self.cloth_live = ti.field(ti.i32, shape=())
        self.cloth_live[None] = self.tri_count
        self._cloth_rows = (cloth_tris, np.concatenate(cloth_of) if cloth_of else
                            np.zeros(0, np.int64), mesh_tris, len(palette) - 1)
        self._surface_version = 0
        self.faces = ti.Vector.field(3, ti.f32, shape=max(count, 1))
        self.surface = ti.field(ti.i32, shape=max(count, 1))
        self.vertices = ti.Vector.field(3, ti.f32, shape=self.particles + self.mesh_vertices)
        self.normals = ti.Vector.field(3, ti.f32, shape=self.particles + self.mesh_vertices)
        self.mesh_row = ti.field(ti.i32, shape=max(self.mesh_vertices, 1))
        self.mesh_moving = ti.field(ti.i32, shape=max(self.mesh_vertices, 1))
        self.palette = ti.Vector.field(3, ti.f32, shape=(len(palette), 2))
        self.palette.from_numpy(palette.astype(np.float32))
        if count:
            self.corners.from_numpy(np.concatenate([cloth_tris, mesh_tris]).astype(np.int32))
            self.surface.from_numpy(np.concatenate(
                cloth_of + [np.full(self.mesh_count, len(palette) - 1)]).astype(np.int32))
        if self.mesh_vertices:
            self.mesh_row.from_numpy(np.concatenate(mesh_rows).astype(np.int32))
            self.mesh_moving.from_numpy(np.concatenate(mesh_moving).astype(np.int32))

    # -- per frame ---------------------------------------------------------------------------
    @contextlib.contextmanager
    def _timed(self, name):
        """Add the seconds the block takes to ``timings[name]`` (where timings is a dict)."""
        if self.timings is None:
            yield
            return
        ti.sync()
        start = clock.perf_counter()
        yield
        ti.sync()
        self.timings[name] = self.timings.get(name, 0.0) + clock.perf_counter() - start

    def render(self):
        """(H,W,3) uint8 image of the simulator's current state."""
        self.sim._check()
        x, time = self.sim.state.x, self.sim.time
        targets = [("camera", self.screen)] + ([("shadow", self.shadow)] if self.shadows else [])
        if not self._static_ready:
            with self._timed("static"):
                self._draw_static([t for _, t in targets], time)
        if self.mesh_count > self.mesh_static:
            with self._timed("meshes.move"):
                self._mesh_world(time, 1)
        if self.tri_count and self.sim.surface_version != self._surface_version:
            self._follow_surface()
        if self.tri_count:
            with self._timed("cloth.drawn"):
                self.cloth.update(x, time)
            with self._timed("cloth.normals"):
                self._cloth_surface()
        for name, target in targets:
            with self._timed(name + ".static"):
                target.restore()
            if self.flying:
                with self._timed(name + ".colliders"):
                    target.cast_moving(self.colliders, self.flying_rows, self.flying_radii,
                                       self.flying, time)
            first = self.tri_count + self.mesh_static
            if self.mesh_count > self.mesh_static:
                with self._timed(name + ".meshes"):
                    target.triangles(self.vertices, self.corners, first,
                                     self.tri_count + self.mesh_count, MESH_ID - self.tri_count)
            if self.tri_count:
                with self._timed(name + ".cloth"):
                    target.triangles(self.vertices, self.corners, 0, self.cloth_live[None], 0)
            if self.sphere_count:
                with self._timed(name + ".spheres"):
                    target.spheres(x, self.sphere_ends, self.sphere_t, self.sphere_count,
                                   self.radius, self.tri_count)
        if self.shadows:
            with self._timed("shadow.summary"):
                self.shadow.summarise()
        with self._timed("shade"):
            self._shade(x, time)
        with self._timed("to_numpy"):
            image = self.image.to_numpy()
        return image

    def _follow_surface(self):
        """The cloth triangles that hold (``Simulator.surface``) first in ``corners``,
        ``cloth_live`` of them, the torn ones after them (neither drawn nor in the vertex
        normals); the mesh colliders' stay where they are."""
        cloth_tris, cloth_of, mesh_tris, collider_row = self._cloth_rows
        held = self.sim.surface()
        order = np.concatenate([np.flatnonzero(held), np.flatnonzero(~held)])
        self.corners.from_numpy(np.concatenate([cloth_tris[order], mesh_tris]).astype(np.int32))
        self.surface.from_numpy(np.concatenate(
            [cloth_of[order], np.full(self.mesh_count, collider_row)]).astype(np.int32))
        self.cloth_live[None] = int(held.sum())
        self._surface_version = self.sim.surface_version

    def _draw_static(self, targets, time):
        """What never moves, into each target's ``static``."""
        if self.mesh_static:
            self._mesh_world(time, 0)
        for target in targets:
            target.clear()
            if self.colliders.count or target.ground is not False:
                target.cast(self.colliders, self.row_moving, time)
            if self.mesh_static:
                target.triangles(self.vertices, self.corners, self.tri_count,
                                 self.tri_count + self.mesh_static, MESH_ID - self.tri_count)
            target.keep()
        self._static_ready = True

    def ids(self):
        """(H*s, W*s) int array: the id seen at each sample of the last render (cloth
        triangles 0.., then spheres; colliders from 2**30, mesh colliders' triangles from
        2**30 + 2**29; ground and sky the largest)."""
        return (self.screen.depth.to_numpy() & 0x7FFFFFFF).astype(np.int32)

    # -- passes ------------------------------------------------------------------------------
    @ti.kernel
    def _mesh_world(self, time: ti.f32, moving: ti.i32):
        """The mesh colliders' vertices, vertex normals and triangles' unit normals in
        the world at ``time`` (``moving``: only the moving ones')."""
        for v in range(self.mesh_vertices):
            if moving == 0 or self.mesh_moving[v] != 0:
                p, n = self.colliders.meshes.world_vertex(
                    self.colliders.data[self.mesh_row[v]], v, time)
                self.vertices[self.particles + v] = ti.cast(p, ti.f32)
                self.normals[self.particles + v] = ti.cast(n, ti.f32)
        for k in range(self.tri_count + self.mesh_static * moving,
                       self.tri_count + self.mesh_count):
            self.faces[k] = self._face(k).normalized()

    @ti.kernel
    def _cloth_surface(self):
        """The cloth where it is drawn, its triangles' unit normals and its vertex
        normals: the sums of their normals of length twice their area about each vertex."""
        for p in range(self.particles):
            self.vertices[p] = self.cloth.x[p]
            self.normals[p] = ti.Vector.zero(ti.f32, 3)
        for k in range(self.tri_count):
            n = self._face(k)
            self.faces[k] = n.normalized()
            if k < self.cloth_live[None]:
                for j in ti.static(range(3)):
                    self.normals[self.corners[k][j]] += n

    @ti.func
    def _face(self, k):
        """Triangle k's normal, of length twice its area."""
        i = self.corners[k]
        a = self.vertices[i[0]]
        return (self.vertices[i[1]] - a).cross(self.vertices[i[2]] - a)


# each simulator's last Renderer and the arguments it was made for (``renderer_for``)
_RENDERERS = weakref.WeakKeyDictionary()


def render(sim: "Simulator", width: int = 640, height: int = 480, *,
           camera: Optional[dict] = None, supersample: int = 2,
           **options: Any) -> np.ndarray:
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
