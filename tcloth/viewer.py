"""The live sandbox: a Taichi GGUI window that simulates a scene and draws it in real time.

Two layers:

  - ``Controls`` (no window): the panel's values and what they do to a ``Simulator``
    (its live setters), picking and dragging a particle with the grab spring, pause /
    step / reset, the integrator switch, and the frame loop's instability handling and
    statistics. Tests drive it directly.
  - ``Viewer``: the GGUI window (cloth with both face colours, particles, colliders,
    ground), the mouse and keys, and the panel that edits ``Controls.values``.

Mouse: left drag pulls the nearest particle under the cursor; right drag orbits the camera;
middle drag (or W / S, Up / Down) zooms (GGUI reports no mouse wheel). Keys: space pauses,
N steps one frame, R resets, Esc quits.
"""
import ctypes
import ctypes.util
import glob
import math
import os
import sys
import time

import numpy as np

from .camera import Camera
from .drawables import cloth_palette, particle_spheres
from .errors import InstabilityError, SceneError
from .integrators import INTEGRATORS
from .render import COLLIDER_COLOUR, PARTICLE_COLOUR, ground_and_checker
from .scene import KIND_CODE, SPRING_KINDS

BACKGROUND = (0.93, 0.94, 0.96)
PANEL_WIDTH = 0.27          # of the window's width, at its left edge
SIDE_OFFSET = 2e-4          # of the scene's extent: how far each cloth side is drawn off it
PICK_ANGLE = 0.05           # rad: the farthest a picked particle may be from the cursor ray


class DisplayError(Exception):
    """No window can be opened here; the message says what is missing and how to get it."""


# -- what a window needs -------------------------------------------------------------------
def check_display():
    """Raise DisplayError unless a GGUI window can open: a display, the Vulkan loader and
    at least one Vulkan driver. GLFW ends the process when it finds no display, so this is
    checked before Taichi is asked."""
    if sys.platform.startswith("linux"):
        if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            raise DisplayError("no display (DISPLAY is not set): run it on a desktop, over "
                               "ssh -X, or under a virtual one: xvfb-run -a tcloth view ... "
                               "(Debian/Ubuntu: apt-get install xvfb)")
        if os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
            name = ctypes.util.find_library("X11")
            xlib = ctypes.CDLL(name) if name else None
            if xlib is not None:
                xlib.XOpenDisplay.restype = ctypes.c_void_p
                if not xlib.XOpenDisplay(None):
                    raise DisplayError(f"cannot open display {os.environ['DISPLAY']!r}: is "
                                       "the X server running and reachable?")
    check_vulkan()


def check_vulkan():
    """Raise DisplayError unless the Vulkan loader and a Vulkan driver are installed."""
    if sys.platform.startswith("linux"):
        if ctypes.util.find_library("vulkan") is None:
            raise DisplayError("no Vulkan loader (libvulkan.so.1): apt-get install libvulkan1 "
                               "mesa-vulkan-drivers (a software driver) or your GPU's driver")
        listed = os.environ.get("VK_DRIVER_FILES") or os.environ.get("VK_ICD_FILENAMES")
        if listed:      # the loader reads only these
            icds = [p for p in listed.split(os.pathsep) if os.path.isfile(p)]
        else:
            icds = [p for d in ("/usr/share/vulkan/icd.d", "/etc/vulkan/icd.d",
                                "/usr/local/share/vulkan/icd.d")
                    for p in glob.glob(os.path.join(d, "*.json"))]
        if not icds:
            raise DisplayError("no Vulkan driver: apt-get install mesa-vulkan-drivers (lavapipe, "
                               "a software driver) or your GPU's Vulkan driver")


# -- camera and picking ----------------------------------------------------------------------
class OrbitCamera:
    """A camera orbiting ``target``: eye, target, world up (y) and vertical fov (degrees)."""

    def __init__(self, camera):
        self.eye, self.target = camera.eye.copy(), camera.target.copy()
        self.fov = camera.fov

    @property
    def basis(self):
        """(forward, right, up) unit vectors."""
        c = Camera(self.eye, self.target, fov=self.fov)
        return c.forward, c.right, c.up

    def orbit(self, yaw, pitch):
        """Turn the eye about the target: yaw about world y, pitch about the camera's right
        (radians), never over the poles."""
        d = self.eye - self.target
        r = np.linalg.norm(d)
        azimuth = math.atan2(d[0], d[2]) - yaw
        elevation = min(max(math.asin(d[1] / r) + pitch, -1.5), 1.5)
        self.eye = self.target + r * np.array([math.cos(elevation) * math.sin(azimuth),
                                               math.sin(elevation),
                                               math.cos(elevation) * math.cos(azimuth)])

    def zoom(self, factor):
        """Scale the eye's distance to the target by factor (> 0)."""
        self.eye = self.target + factor * (self.eye - self.target)

    def ray(self, u, v, aspect):
        """(origin, unit direction) of the ray through window point (u, v), both in [0, 1]
        from the bottom left (GGUI's cursor), for width / height = aspect."""
        forward, right, up = self.basis
        half = math.tan(math.radians(self.fov) / 2)
        d = forward + (2 * u - 1) * half * aspect * right + (2 * v - 1) * half * up
        return self.eye.copy(), d / np.linalg.norm(d)


def pick(positions, candidates, origin, direction, max_angle=PICK_ANGLE):
    """The id among ``candidates`` whose direction from origin is closest to ``direction``
    (within max_angle radians, in front of the origin), nearest first on ties; or None."""
    if len(candidates) == 0:
        return None
    d = positions[candidates] - origin
    dist = np.linalg.norm(d, axis=1)
    cosine = d @ direction / np.maximum(dist, 1e-30)
    angle = np.arccos(np.clip(cosine, -1.0, 1.0))
    ok = angle <= max_angle
    if not ok.any():
        return None
    order = np.lexsort((dist[ok], np.round(angle[ok], 4)))
    return int(candidates[np.flatnonzero(ok)[order[0]]])


# -- the panel's state and what it does ------------------------------------------------------
class Controls:
    """The sandbox's logic for one Simulator, without a window.

    ``values`` holds what the panel shows and edits: dt (s), substeps (per frame),
    gravity (m/s^2, downwards along -y), springs {kind: [k_s, k_d]} for the kinds the
    scene has, wind_speed (m/s) and wind_direction (degrees about y, 0 = +x) when the scene
    has wind (not a Python-callable gust, which sets the velocity itself), colliders (one
    bool each), strain_limiting (when the scene has a limit).
    ``apply()`` hands every changed value to the simulator's live setters.
    """

    def __init__(self, sim, substeps=10):
        self.sim = sim
        scene = sim.scene
        springs = scene.springs
        kinds = {k: springs["kind"] == KIND_CODE[k] for k in SPRING_KINDS}
        self.values = {"dt": sim.dt, "substeps": int(substeps),
                       "gravity": float(-scene.gravity[1]),
                       "springs": {k: [_typical(springs[q][mask])
                                       for q in ("stiffness", "damping")]
                                   for k, mask in kinds.items() if mask.any()},
                       "colliders": [i not in sim.settings["colliders_off"]
                                     for i in range(len(scene.colliders))]}
        if sim.model.wind is not None and scene.wind["callable"] is None:
            w = scene.wind["velocity"]
            self.values["wind_speed"] = float(np.hypot(w[0], w[2]))
            self.values["wind_direction"] = float(np.degrees(np.arctan2(w[2], w[0])))
        if scene.strain_limit is not None:
            self.values["strain_limiting"] = sim.settings["strain_limiting"]
        self.initial = _copy(self.values)
        self._applied = _copy(self.values)
        self.paused = False
        self.message = ""
        self.frame_seconds = []
        self.substep_seconds = []
        self.dragging = None            # (particle, depth along the view) while held
        self._measured, self._stats_age = None, 0
        self.pickable = np.flatnonzero(~scene.pinned)

    # -- panel values -> simulator ---------------------------------------------------------
    def apply(self):
        """Hand every value changed since the last apply to the simulator."""
        new, old, sim = self.values, self._applied, self.sim
        if new["dt"] != old["dt"]:
            sim.set_dt(new["dt"])
        if new["gravity"] != old["gravity"]:
            g = sim.scene.gravity.copy()
            g[1] = -new["gravity"]
            sim.set_gravity(g)
        for kind, (ks, kd) in new["springs"].items():
            if [ks, kd] != old["springs"][kind]:
                sim.set_springs(kind, stiffness=ks, damping=kd)
        if "wind_speed" in new and (new["wind_speed"], new["wind_direction"]) != \
                (old["wind_speed"], old["wind_direction"]):
            a = math.radians(new["wind_direction"])
            vy = sim.scene.wind["velocity"][1]
            sim.set_wind((new["wind_speed"] * math.cos(a), vy, new["wind_speed"] * math.sin(a)))
        for i, (on, was) in enumerate(zip(new["colliders"], old["colliders"])):
            if on != was:
                sim.set_collider_enabled(i, on)
        if "strain_limiting" in new and new["strain_limiting"] != old["strain_limiting"]:
            sim.set_strain_limiting(new["strain_limiting"])
        self._applied = _copy(new)

    def set_integrator(self, name):
        """Continue from the current state with another integrator."""
        self.sim.set_integrator(name)
        self.message = ""

    def reset(self):
        """Back to t = 0 with the panel's initial values; unpaused."""
        self.end_drag()
        self.values = _copy(self.initial)
        self.apply()
        self.sim.reset()
        self.message = ""
        self.paused = False

    # -- stepping --------------------------------------------------------------------------
    def advance(self, force=False):
        """One frame of ``substeps`` steps unless paused (force: even when paused). On
        InstabilityError the simulator keeps its last good state, the viewer pauses and
        ``message`` holds the error and its hint until the next frame that runs (after the
        user resumes, perhaps with other settings). Returns True when it stepped."""
        if self.paused and not force:
            return False
        self.message = ""
        start = time.perf_counter()
        try:
            self.sim.step(self.values["substeps"])      # waits: each step reads its check
        except InstabilityError as e:
            self.message = str(e)
            self.paused = True
            return False
        elapsed = time.perf_counter() - start
        self.substep_seconds = (self.substep_seconds + [elapsed / self.values["substeps"]])[-30:]
        return True

    def frame_done(self, seconds):
        self.frame_seconds = (self.frame_seconds + [seconds])[-30:]

    def stats(self, every=1):
        """dict: fps, ms_per_substep (medians of the last 30 frames), energy (J),
        max_strain, time (s), integrator, contacts (``Simulator.contact_stats``). every=k
        reuses the energy, strain and contacts of the last call for k - 1 calls (the
        panel: they cost more than a 64 x 64 cloth's frame)."""
        sim = self.sim
        self._stats_age += 1
        if self._measured is None or self._stats_age >= every:
            self._measured = {"energy": sim.energy()["total"], "max_strain": sim.max_strain(),
                              "contacts": sim.contact_stats()}
            self._stats_age = 0
        return {"fps": 1.0 / np.median(self.frame_seconds) if self.frame_seconds else 0.0,
                "ms_per_substep": 1e3 * np.median(self.substep_seconds)
                if self.substep_seconds else 0.0,
                **self._measured, "time": sim.time, "integrator": sim.integrator_name}

    # -- dragging --------------------------------------------------------------------------
    def start_drag(self, camera, u, v, aspect):
        """Grab the free particle under window point (u, v); returns its id or None."""
        if self.sim.model.grab is None:
            return None
        origin, direction = camera.ray(u, v, aspect)
        x = self.sim.positions().astype(np.float64)
        p = pick(x, self.pickable, origin, direction)
        if p is None:
            return None
        forward = camera.basis[0]
        self.dragging = (p, float((x[p] - origin) @ forward))
        self.sim.grab(p, x[p])
        return p

    def drag(self, camera, u, v, aspect):
        """Move the held particle's target to the cursor, at the depth it was grabbed at."""
        if self.dragging is None:
            return
        p, depth = self.dragging
        origin, direction = camera.ray(u, v, aspect)
        held = self.sim.grabbed
        self.sim.grab(p, origin + direction * depth / (direction @ camera.basis[0]),
                      held["stiffness"], held["damping"])

    def end_drag(self):
        self.dragging = None
        self.sim.release()


def _typical(values):
    """The common value of equal values, else their mean."""
    return float(values[0] if np.all(values == values[0]) else np.mean(values))


def _copy(values):
    return {k: ({kk: list(vv) for kk, vv in v.items()} if isinstance(v, dict) else
                list(v) if isinstance(v, list) else v) for k, v in values.items()}


# -- meshes (NumPy) ------------------------------------------------------------------------
def vertex_normals(x, triangles):
    """(N,3) unit area-weighted vertex normals of the triangles (0 where a vertex has
    none)."""
    a, b, c = (x[triangles[:, k]] for k in range(3))
    face = np.cross(b - a, c - a)
    ids = triangles.T.ravel()
    n = np.stack([np.bincount(ids, np.tile(face[:, d], 3), len(x)) for d in range(3)], 1)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def _sphere_mesh(centre, radius, rings=16, sectors=32):
    theta = np.linspace(0, np.pi, rings + 1)[:, None]
    phi = np.linspace(0, 2 * np.pi, sectors + 1)[None, :]
    unit = np.stack([np.sin(theta) * np.cos(phi), np.cos(theta) * np.ones_like(phi),
                     np.sin(theta) * np.sin(phi)], -1).reshape(-1, 3)
    return centre + radius * unit, _grid_triangles(rings, sectors)


def _grid_triangles(rows, cols):
    """Two triangles per cell of a (rows + 1) x (cols + 1) vertex grid, wound so that a
    sphere's outside (and a tile's +y side) is the front."""
    r, c = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    a = (r * (cols + 1) + c).ravel()
    b, d = a + 1, a + cols + 1
    return np.concatenate([np.stack([a, b, d], 1), np.stack([b, d + 1, d], 1)])


def _cylinder_mesh(radius, half, sectors=32):
    phi = np.linspace(0, 2 * np.pi, sectors + 1)
    ring = np.stack([radius * np.cos(phi), np.zeros_like(phi), radius * np.sin(phi)], 1)
    side = np.concatenate([ring + (0, half, 0), ring - (0, half, 0)])
    caps = np.array([[0, half, 0], [0, -half, 0]])
    v = np.concatenate([side, caps])
    n = sectors + 1
    k = np.arange(sectors)
    tris = np.concatenate([np.stack([k, k + 1, n + k], 1), np.stack([k + 1, n + k + 1, n + k], 1),
                           np.stack([np.full(sectors, 2 * n), k + 1, k], 1),
                           np.stack([np.full(sectors, 2 * n + 1), n + k, n + k + 1], 1)])
    return v, tris


def _box_mesh(half):
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * half
    faces = ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3))
    v = np.concatenate([corners[list(f)] for f in faces])
    base = 4 * np.arange(6)[:, None]
    tris = np.concatenate([base + (0, 1, 2), base + (0, 2, 3)])
    return v, tris


def tiles(centre, normal, half, size):
    """A checkered square of side 2 half, centred on centre, facing normal: (vertices,
    triangles, colours), tiles of side ``size`` with their own vertices."""
    n = np.asarray(normal, dtype=np.float64) / np.linalg.norm(normal)
    a = np.cross(n, (1.0, 0.0, 0.0) if abs(n[0]) < 0.9 else (0.0, 0.0, 1.0))
    a /= np.linalg.norm(a)
    b = np.cross(a, n)
    k = max(1, min(int(2 * half / size), 32))
    step = 2 * half / k
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    i, j = i.ravel(), j.ravel()
    quad = np.array([(0, 0), (1, 0), (1, 1), (0, 1)])
    s = (i[:, None] + quad[None, :, 0]) * step - half
    t = (j[:, None] + quad[None, :, 1]) * step - half
    v = (np.asarray(centre) + s[..., None] * a + t[..., None] * b).reshape(-1, 3)
    base = 4 * np.arange(k * k)[:, None]
    tris = np.concatenate([base + (0, 2, 1), base + (0, 3, 2)])
    shade = np.where((i + j) % 2 == 0, 0.82, 0.68)
    colours = np.repeat(np.stack([shade, shade, shade * 1.02], 1), 4, axis=0).clip(0, 1)
    return v, tris, colours


def collider_mesh(collider, t, half):
    """(vertices, triangles) of a scene collider at time t; planes are a square of side
    2 half around their point."""
    centre = np.asarray(collider["center"]) + t * np.asarray(collider["velocity"])
    kind = collider["kind"]
    if kind == "sphere":
        return _sphere_mesh(centre, collider["radius"])
    if kind == "plane":
        v, tris, _ = tiles(centre, collider["normal"], half, 2 * half)
        return v, tris
    if kind == "box":
        v, tris = _box_mesh(np.asarray(collider["half_extents"]))
    else:
        v, tris = _cylinder_mesh(collider["radius"], collider["half_height"])
    return centre + v @ np.asarray(collider["rotation"]).T, tris


# -- the window ------------------------------------------------------------------------------
class Viewer:
    """A GGUI window on a Simulator.

    Args:
        sim: the Simulator (made with grab=True to drag particles).
        substeps: simulator steps per frame. camera: None (fit), dict or Camera.
        width, height: window size, pixels. ground: as the off-screen Renderer's.
        cloth_colours: as the off-screen Renderer's.
    """

    def __init__(self, sim, substeps=10, camera=None, width=1280, height=800, ground=None,
                 cloth_colours=None, title="tcloth"):
        import taichi as ti
        self.ti = ti
        check_display()
        self.controls = Controls(sim, substeps)
        self.sim = sim
        scene = sim.scene
        x0 = scene.positions
        self.camera = OrbitCamera(Camera.from_config(camera, x0))
        self.size = (int(width), int(height))
        try:
            self.window = ti.ui.Window(title, self.size, vsync=False)
        except RuntimeError as e:
            raise DisplayError(f"cannot open a window: {e} (a Vulkan driver: apt-get install "
                               "mesa-vulkan-drivers libvulkan1)") from None
        self.canvas = self.window.get_canvas()
        self.scene3d = self.window.get_scene()
        self.gui = self.window.get_gui()
        self.ggui_camera = ti.ui.Camera()
        lo, hi = x0.min(0), x0.max(0)
        self.extent = float(np.linalg.norm(hi - lo)) or 1.0
        self.centre = 0.5 * (lo + hi)
        self._build_cloth(scene, cloth_colours)
        self._build_spheres(scene)
        self._build_static(scene, ground)
        self._last_cursor = None

    # -- fields ------------------------------------------------------------------------------
    def _build_cloth(self, scene, cloth_colours):
        ti = self.ti
        tris = [c.triangles for c in scene.cloths]
        n = scene.num_particles
        self.front_x, self.back_x, self.front_n, self.back_n = (
            ti.Vector.field(3, ti.f32, shape=n) for _ in range(4))
        self.tri_count = sum(len(t) for t in tris)
        if not self.tri_count:
            return
        palette = cloth_palette(cloth_colours, len(tris))
        all_tris = self.triangles = np.concatenate(tris).astype(np.int32)
        self.front_idx = ti.field(ti.i32, shape=3 * self.tri_count)
        self.back_idx = ti.field(ti.i32, shape=3 * self.tri_count)
        self.front_idx.from_numpy(all_tris.ravel())
        self.back_idx.from_numpy(all_tris[:, ::-1].ravel().copy())
        colours = np.zeros((2, n, 3), dtype=np.float32)
        for k, c in enumerate(scene.cloths):
            colours[:, c.particles.ravel()] = palette[k][:, None, :]
        self.front_c = ti.Vector.field(3, ti.f32, shape=n)
        self.back_c = ti.Vector.field(3, ti.f32, shape=n)
        self.front_c.from_numpy(colours[0])
        self.back_c.from_numpy(colours[1])

    def _build_spheres(self, scene):
        ti = self.ti
        spheres, self.radius = particle_spheres(scene, None, self.extent)
        self.sphere_count = len(spheres)
        if self.sphere_count:
            self.sphere_ends = spheres[:, :2].astype(np.int64)
            self.sphere_t = spheres[:, 2:3]
            self.sphere_x = ti.Vector.field(3, ti.f32, shape=self.sphere_count)

    def _mesh_fields(self, vertices, triangles, colours=None):
        """GGUI fields of a collider or ground mesh: vertices, indices, normals (computed
        once: a collider moves without turning), colours or None."""
        ti = self.ti
        fields = []
        for values in (vertices, vertex_normals(vertices, triangles), colours):
            if values is None:
                fields.append(None)
                continue
            f = ti.Vector.field(3, ti.f32, shape=len(vertices))
            f.from_numpy(values.astype(np.float32))
            fields.append(f)
        idx = ti.field(ti.i32, shape=3 * len(triangles))
        idx.from_numpy(triangles.astype(np.int32).ravel())
        return fields[0], idx, fields[1], fields[2]

    def _draw_mesh(self, fields):
        v, idx, normals, colours = fields
        if colours is not None:
            self.scene3d.mesh(v, indices=idx, normals=normals, per_vertex_color=colours,
                              two_sided=True)
        else:
            self.scene3d.mesh(v, indices=idx, normals=normals, color=COLLIDER_COLOUR)

    def _build_static(self, scene, ground):
        ground, size = ground_and_checker(scene, ground, self.extent)
        self.ground = None
        half = 3 * self.extent
        if ground is not False:
            self.ground = self._mesh_fields(*tiles((self.centre[0], ground, self.centre[2]),
                                                   (0, 1, 0), half, size))
        self.colliders = []
        for c in scene.colliders:
            if c["kind"] == "plane":
                fields = self._mesh_fields(*tiles(c["center"], c["normal"], half, size))
            else:
                fields = self._mesh_fields(*collider_mesh(c, 0.0, half))
            self.colliders.append((c, fields, bool(np.any(c["velocity"] != 0))))

    # -- per frame ---------------------------------------------------------------------------
    def _draw(self):
        sim, s3 = self.sim, self.scene3d
        cam = self.camera
        self.ggui_camera.position(*cam.eye)
        self.ggui_camera.lookat(*cam.target)
        self.ggui_camera.up(0.0, 1.0, 0.0)
        self.ggui_camera.fov(cam.fov)
        s3.set_camera(self.ggui_camera)
        s3.ambient_light((0.45, 0.45, 0.45))
        s3.point_light(tuple(self.centre + 4 * self.extent * np.array([0.35, 0.85, 0.4])),
                       (0.7, 0.7, 0.7))
        s3.point_light(tuple(cam.eye), (0.35, 0.35, 0.35))
        x = sim.positions().astype(np.float64)
        if self.tri_count:
            # each side a hair off the surface towards its own side, so that the side facing
            # the camera wins the depth test (GGUI draws both sides of every triangle)
            normals = vertex_normals(x, self.triangles)
            offset = SIDE_OFFSET * self.extent * normals
            self.front_x.from_numpy((x + offset).astype(np.float32))
            self.back_x.from_numpy((x - offset).astype(np.float32))
            self.front_n.from_numpy(normals.astype(np.float32))
            self.back_n.from_numpy(-normals.astype(np.float32))
            s3.mesh(self.front_x, indices=self.front_idx, normals=self.front_n,
                    per_vertex_color=self.front_c)
            s3.mesh(self.back_x, indices=self.back_idx, normals=self.back_n,
                    per_vertex_color=self.back_c)
        if self.sphere_count:
            a, b = x[self.sphere_ends[:, 0]], x[self.sphere_ends[:, 1]]
            self.sphere_x.from_numpy((a + self.sphere_t * (b - a)).astype(np.float32))
            s3.particles(self.sphere_x, radius=self.radius, color=PARTICLE_COLOUR)
        if self.ground is not None:
            self._draw_mesh(self.ground)
        enabled = self.controls.values["colliders"]
        for k, (col, fields, moving) in enumerate(self.colliders):
            if not enabled[k]:
                continue
            if moving:
                fields[0].from_numpy(
                    collider_mesh(col, sim.time, 3 * self.extent)[0].astype(np.float32))
            self._draw_mesh(fields)
        held = sim.grabbed
        if held is not None:
            self._grab_line(x[held["particle"]], held["target"])
        self.canvas.set_background_color(BACKGROUND)
        self.canvas.scene(s3)

    def _grab_line(self, a, b):
        ti = self.ti
        if not hasattr(self, "_line"):
            self._line = ti.Vector.field(3, ti.f32, shape=2)
        self._line.from_numpy(np.array([a, b], dtype=np.float32))
        self.scene3d.lines(self._line, width=2.0, color=(0.1, 0.1, 0.1))

    def _panel(self):
        c, gui, v = self.controls, self.gui, self.controls.values
        with gui.sub_window("tcloth", 0.0, 0.0, PANEL_WIDTH, 1.0) as w:
            st = c.stats(every=10)
            w.text(f"{st['fps']:.0f} frames/s, {st['ms_per_substep']:.3f} ms/substep")
            w.text(f"t = {st['time']:.3f} s   energy {st['energy']:.4g} J")
            w.text(f"max strain {100 * st['max_strain']:.1f} %")
            for line in contact_lines(st["contacts"]):
                w.text(line)
            if c.message:
                w.text("UNSTABLE (last good state kept):", color=(0.8, 0.1, 0.1))
                for line in _wrap(c.message, 44):
                    w.text(line)
            if w.button("Run" if c.paused else "Pause"):
                c.paused = not c.paused
            if w.button("Step"):
                c.advance(force=True)
            if w.button("Reset"):
                c.reset()
            w.text(f"integrator: {st['integrator']}")
            for name in INTEGRATORS:
                if name != st["integrator"] and w.button(name):
                    c.set_integrator(name)
            v["dt"] = 1e-3 * w.slider_float("dt (ms)", 1e3 * v["dt"], 1e2 * c.initial["dt"],
                                            4e3 * c.initial["dt"])
            v["substeps"] = w.slider_int("substeps", v["substeps"], 1,
                                         max(4 * c.initial["substeps"], 16))
            v["gravity"] = w.slider_float("gravity", v["gravity"], 0.0, 20.0)
            for kind, pair in v["springs"].items():
                k0, d0 = c.initial["springs"][kind]
                pair[0] = w.slider_float(f"{kind} k_s", pair[0], 0.0, max(10 * k0, 1.0))
                pair[1] = w.slider_float(f"{kind} k_d", pair[1], 0.0, max(10 * d0, 0.1))
            if "wind_speed" in v:
                v["wind_speed"] = w.slider_float("wind m/s", v["wind_speed"], 0.0, 20.0)
                v["wind_direction"] = w.slider_float("wind dir", v["wind_direction"],
                                                     -180.0, 180.0)
            for k, (col, _, _) in enumerate(self.colliders):
                v["colliders"][k] = w.checkbox(f"{col['kind']} {k}", v["colliders"][k])
            if "strain_limiting" in v:
                v["strain_limiting"] = w.checkbox("strain limiting", v["strain_limiting"])

    def _input(self):
        ti, win = self.ti, self.window
        for e in win.get_events():
            if e.key == ti.ui.ESCAPE and e.type == ti.ui.PRESS:
                win.running = False
            elif e.type == ti.ui.PRESS and e.key == ti.ui.SPACE:
                self.controls.paused = not self.controls.paused
            elif e.type == ti.ui.PRESS and e.key in ("n", "N"):
                self.controls.advance(force=True)
            elif e.type == ti.ui.PRESS and e.key in ("r", "R"):
                self.controls.reset()
            elif e.key == ti.ui.LMB:
                u, v = win.get_cursor_pos()
                if e.type == ti.ui.PRESS and u > PANEL_WIDTH:
                    self.controls.start_drag(self.camera, u, v, self.size[0] / self.size[1])
                elif e.type == ti.ui.RELEASE:
                    self.controls.end_drag()
        u, v = win.get_cursor_pos()
        if self.controls.dragging is not None:
            self.controls.drag(self.camera, u, v, self.size[0] / self.size[1])
        if self._last_cursor is not None:
            du, dv = u - self._last_cursor[0], v - self._last_cursor[1]
            if win.is_pressed(ti.ui.RMB):
                self.camera.orbit(3.0 * du, -3.0 * dv)
            if win.is_pressed(ti.ui.MMB):
                self.camera.zoom(math.exp(-2.0 * dv))
        if win.is_pressed("w", ti.ui.UP):
            self.camera.zoom(0.97)
        if win.is_pressed("s", ti.ui.DOWN):
            self.camera.zoom(1.03)
        self._last_cursor = (u, v)

    def frame(self):
        """One frame: input, panel, the simulator's substeps, drawing."""
        start = time.perf_counter()
        self._input()
        self._panel()
        self.controls.apply()
        self.controls.advance()
        self._draw()
        return start

    def run(self, frames=None, screenshot=None):
        """Run until the window closes, or ``frames`` frames; then save the window's image
        to ``screenshot`` (PNG) when given."""
        count = 0
        while self.window.running and (frames is None or count < frames):
            start = self.frame()
            if screenshot is not None and frames is not None and count == frames - 1:
                self.window.save_image(screenshot)
            self.window.show()
            self.controls.frame_done(time.perf_counter() - start)
            count += 1
        return count


def contact_lines(stats):
    """The panel's lines for ``Simulator.contact_stats()`` (none for a scene without
    contact): the contacts active now, then what the stage did so far."""
    if not stats:
        return []
    lines = []
    if stats.get("rebuilds"):
        lines.append(f"self-contacts: {stats['point_triangle']} point-triangle, "
                     f"{stats['edge_edge']} edge-edge")
        lines.append(f"  {stats['candidates']} candidates, {stats['rebuilds']} rebuilds")
        lines.append(f"  guard: {stats['guard_corrections']} corrections, "
                     f"{stats['failsafe_steps']} fail-safe steps")
    lines.append(f"collider contacts: {stats['collider']}, "
                 f"{stats['collider_paths_cut']} paths cut")
    lines.append(f"contact stage: {stats['seconds']:.2f} s so far")
    return lines


def _wrap(text, width):
    lines, line = [], ""
    for word in text.split():
        if line and len(line) + 1 + len(word) > width:
            lines.append(line)
            line = word
        else:
            line = f"{line} {word}".strip()
    return lines + [line] if line else lines


def view(sim, substeps=10, camera=None, frames=None, screenshot=None, **options):
    """Open the sandbox window on ``sim`` (see ``Viewer``); returns the frames shown."""
    try:
        viewer = Viewer(sim, substeps=substeps, camera=camera, **options)
    except DisplayError as e:
        raise SceneError(f"cannot open the viewer: {e}") from None
    return viewer.run(frames=frames, screenshot=screenshot)
