"""The sandbox's GGUI window on a Simulator: the cloth with both face colours, particles,
colliders and ground drawn each frame, the mouse and keys, and the panel that edits
``Controls.values``.

Mouse: left drag pulls the nearest particle under the cursor; right drag orbits the camera;
middle drag (or W / S, Up / Down) zooms (GGUI reports no mouse wheel). Keys: space pauses,
N steps one frame, R resets, Esc quits.
"""
import math
import time

import numpy as np

from ..render.camera import Camera
from ..render.drawables import (COLLIDER_COLOUR, PARTICLE_COLOUR, DrawnCloth, cloth_palette,
                                particle_spheres)
from ..errors import SceneError
from ..integrators import INTEGRATORS
from ..render.framing import ground_and_checker
from .camera import OrbitCamera
from .controls import Controls, contact_lines, split_line
from .display import DisplayError, check_display
from .meshes import collider_mesh, collider_moves, tiles, vertex_normals

BACKGROUND = (0.93, 0.94, 0.96)
PANEL_WIDTH = 0.27          # of the window's width, at its left edge
SIDE_OFFSET = 2e-4          # of the scene's extent: how far each cloth side is drawn off it


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
        all_tris = self.all_triangles = np.concatenate(tris).astype(np.int32)
        self.drawn = DrawnCloth(self.sim.model.colliders, all_tris, n)
        self.front_idx = ti.field(ti.i32, shape=3 * self.tri_count)
        self.back_idx = ti.field(ti.i32, shape=3 * self.tri_count)
        self._surface_version = None
        self._follow_surface()
        colours = np.zeros((2, n, 3), dtype=np.float32)
        for k, c in enumerate(scene.cloths):
            colours[:, c.particles.ravel()] = palette[k][:, None, :]
        self.front_c = ti.Vector.field(3, ti.f32, shape=n)
        self.back_c = ti.Vector.field(3, ti.f32, shape=n)
        self.front_c.from_numpy(colours[0])
        self.back_c.from_numpy(colours[1])

    def _follow_surface(self):
        """The cloth triangles that hold (``Simulator.surface``: all but those a tear cut)
        first in the index fields, ``triangles`` of them drawn."""
        if self.sim.surface_version == self._surface_version:
            return
        held = self.sim.surface()
        tris = self.all_triangles[np.concatenate([np.flatnonzero(held), np.flatnonzero(~held)])]
        self.front_idx.from_numpy(tris.ravel())
        self.back_idx.from_numpy(tris[:, ::-1].ravel().copy())
        self.triangles = self.all_triangles[held]
        self._surface_version = self.sim.surface_version

    def _build_spheres(self, scene):
        ti = self.ti
        spheres, self.radius = particle_spheres(scene, None, self.extent)
        self.sphere_count = len(spheres)
        if self.sphere_count:
            self.sphere_ends = spheres[:, :2].astype(np.int64)
            self.sphere_t = spheres[:, 2:3]
            self.sphere_x = ti.Vector.field(3, ti.f32, shape=self.sphere_count)

    def _mesh_fields(self, vertices, triangles, colours=None):
        """GGUI fields of a collider or ground mesh: vertices, indices, normals (a moving
        mesh collider's are set again each frame, ``_draw``), colours or None."""
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
        self.tile = size
        self.colliders = []
        for c in scene.colliders:
            fields = self._mesh_fields(*collider_mesh(c, 0.0, half, size))
            self.colliders.append((c, fields, collider_moves(c)))

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
            self._follow_surface()
        if self.tri_count and len(self.triangles):
            # where the off-screen renderer draws it too: out of the colliders it rests on
            y = self.drawn.update(sim.state.x, sim.time).to_numpy().astype(np.float64)
            # each side a hair off the surface towards its own side, so that the side facing
            # the camera wins the depth test (GGUI draws both sides of every triangle)
            normals = vertex_normals(y, self.triangles)
            offset = SIDE_OFFSET * self.extent * normals
            self.front_x.from_numpy((y + offset).astype(np.float32))
            self.back_x.from_numpy((y - offset).astype(np.float32))
            self.front_n.from_numpy(normals.astype(np.float32))
            self.back_n.from_numpy(-normals.astype(np.float32))
            count = 3 * len(self.triangles)
            s3.mesh(self.front_x, indices=self.front_idx, normals=self.front_n,
                    per_vertex_color=self.front_c, index_count=count)
            s3.mesh(self.back_x, indices=self.back_idx, normals=self.back_n,
                    per_vertex_color=self.back_c, index_count=count)
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
                v, tris, _ = collider_mesh(col, sim.time, 3 * self.extent, self.tile)
                fields[0].from_numpy(v.astype(np.float32))
                fields[2].from_numpy(vertex_normals(v, tris).astype(np.float32))
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
            if self.sim.scene.tearing is not None:
                w.text(f"torn springs: {len(self.sim.torn())}")
            w.text(split_line(st["splits"]))
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
            v["air_damping"] = w.slider_float("air damping (1/s)", v["air_damping"], 0.0,
                                              max(10 * c.initial["air_damping"], 10.0))
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
