"""Model (static Taichi fields built once from a Scene) and State (per-step fields).

Pinned particles are ordinary particles with inverse mass 0. Springs live in one list
ordered so that the springs the force kernels walk one by one come first
(``list_spring_count`` of them); springs of cloths handled by the grid stencil follow and
are only read by diagnostics and the implicit solvers. Cloth grids are described by
``grid.GridBlock`` records, colliders by a ``collider_table.ColliderTable``.

A Model's layout never changes after it is built: scratch buffers belong to the terms and
integrators that use them. Its values may: ``refresh`` uploads the scene's current
gravity, drag, spring parameters, wind and colliders into the same fields (nothing is
recompiled), and the ``grab`` spring (when built) is moved at run time. These are what
``Simulator``'s live setters change.
"""
import numpy as np
import taichi as ti

from .. import runtime
from ..errors import SceneError
from ..features import FEATURES
from .grid import GridBlock, GridTable
from .collider_table import ColliderTable


def _vec_field(n):
    return ti.Vector.field(3, runtime.real(), shape=n)


@ti.kernel
def _copy_state(out: ti.template(), src: ti.template()):
    ti.loop_config(serialize=ti.static(runtime.serial(out.x)))
    for p in range(out.x.shape[0]):
        out.x[p], out.v[p], out.f[p] = src.x[p], src.v[p], src.f[p]


def copy_state(out, src):
    """State ``out``'s x, v, f and t made ``src``'s (one launch)."""
    _copy_state(out, src)
    out.t = src.t


@ti.data_oriented
class State:
    """Per-step particle state (kernels and ``ti.func``s take a State whole).

    Attributes:
        x: positions, shape (particle_count,) of vec3, m.
        v: velocities, shape (particle_count,) of vec3, m/s.
        f: force accumulator, shape (particle_count,) of vec3, N.
        t: the time of this state, s (moving colliders depend on it).
    """

    def __init__(self, n):
        self.x = _vec_field(n)
        self.v = _vec_field(n)
        self.f = _vec_field(n)
        self.t = 0.0


class Model:
    """Static description of a scene as Taichi fields.

    Attributes:
        particle_count, spring_count, list_spring_count: sizes.
        mass, inv_mass: shape (particle_count,), kg and 1/kg (0 = pinned).
        params: shape (4,): (g_x, g_y, g_z, air_drag), m/s^2 and N s/m (air_drag alone:
            the drag a particle feels is ``drag``).
        drag: shape (particle_count,): each particle's viscous drag coefficient
            c + gamma m_p from the scene's air_drag c and air_damping gamma, N s/m.
        spring_pairs: shape (spring_count,) of 2 x i32 particle ids.
        spring_rest, spring_ks, spring_kd: shape (spring_count,); m, N/m, N s/m.
        grids: list of GridBlock (empty when grid_stencil=False); grid_table: their
            numbers as fields (``grid.GridTable``).
        spring_order: (spring_count,) the scene spring id of each model row.
        colliders: ``collider_table.ColliderTable``.
        one attribute per scene feature (``features.FEATURES``), named as the feature: the
            object its ``build`` made of the scene's value (its class documents each
            field), or None where the scene does not set it. The Model has no other
            attribute of a feature's. They are:
            bending: ``features.bending.BendingData``: count, hinges, weights, start,
                entries, diagonal;
            membrane: ``features.membrane.MembraneData``: count, triangles, weights,
                coefficients, start, entries;
            wind: ``features.wind.WindData`` (None without cloth triangles): settings (the
                scene's wind dict), triangles, params;
            attraction: ``features.attraction.AttractionData``: G, softening;
            pressure: ``features.pressure.PressureData``: triangles, chamber, gas, start,
                entries;
            self_collision: ``contact.topology.SelfCollisionTable``;
            strain_limit: ``features.strain_limit.StrainLimitData``: count, index,
                max_stretch, iterations;
            tearing: ``features.tearing.TearingData``: count, rows, max_strain, alive,
                broken, torn, rows_broken, gridded, grid_alive, grid_slot.
        grab: the grab spring (``terms.grab.GrabSpring``, the mouse spring of the viewer)
            or None.

    Args:
        scene: the Scene. grid_stencil: see ``Simulator``.
        colliders_off: scene indices of colliders switched off (stiffness 0).
        grab: the grab spring to carry, or None.
    """

    def __init__(self, scene, grid_stencil=True, colliders_off=(), grab=None):
        self.generation = runtime.ensure_init()
        self.scene = scene
        self.particle_count = n = scene.num_particles
        if n == 0:
            raise SceneError("scene has no particles (got num_particles = 0)")
        npr = runtime.numpy_real()
        real = runtime.real()
        # kernel parameters live in fields: vector kernel arguments cost Python time a launch
        self.params = ti.field(real, shape=4)

        self.mass = ti.field(real, shape=n)
        self.inv_mass = ti.field(real, shape=n)
        self.drag = ti.field(real, shape=n)

        springs = scene.springs
        in_grid = np.zeros(scene.num_springs, dtype=bool)
        self.grids = []
        if grid_stencil:
            for cloth in (c for c in scene.cloths if c.is_grid and c.stencil):
                for sids in cloth.springs.values():
                    in_grid[sids] = True
                self.grids.append(self._grid_block(cloth))
        self.grid_table = GridTable(self.grids)
        self.spring_order = order = np.argsort(in_grid, kind="stable")
        self.spring_count = ns = scene.num_springs
        self.list_spring_count = int((~in_grid).sum())
        self.spring_pairs = ti.Vector.field(2, ti.i32, shape=max(ns, 1))
        self.spring_rest = ti.field(real, shape=max(ns, 1))
        self.spring_ks = ti.field(real, shape=max(ns, 1))
        self.spring_kd = ti.field(real, shape=max(ns, 1))
        if ns:
            self.spring_pairs.from_numpy(springs["pairs"][order].astype(np.int32))
            self.spring_rest.from_numpy(springs["rest_length"][order].astype(npr))

        for feature in FEATURES:
            value = getattr(scene, feature.name)
            setattr(self, feature.name, None if value is None else feature.build(self, value))
        self.colliders = ColliderTable(scene.colliders, colliders_off)
        self.grab = grab
        self.refresh(colliders_off)

    @staticmethod
    def _grid_block(cloth):
        p = cloth.params
        return GridBlock(cloth.offset, *cloth.resolution, *cloth.spacing,
                         p["structural"], p["shear"], p["flexion"])

    def refresh(self, colliders_off=()):
        """Upload the scene's current masses, gravity and drag, spring stiffness and
        damping, live features (the wind) and colliders (those in ``colliders_off``
        switched off) into the model's fields.
        The scene's layout (particles, springs, cloths, which terms exist) must be the one
        the model was built from."""
        scene, npr = self.scene, runtime.numpy_real()
        masses = scene.masses
        self.mass.from_numpy(masses.astype(npr))
        self.inv_mass.from_numpy(np.where(scene.pinned, 0.0, 1.0 / masses).astype(npr))
        if self.membrane is not None:
            self.membrane.masses_changed(masses)
        self.params.from_numpy(np.array([*scene.gravity, scene.air_drag], dtype=npr))
        self.drag.from_numpy(scene.drag_coefficients().astype(npr))
        if self.spring_count:
            springs = scene.springs
            self.spring_ks.from_numpy(springs["stiffness"][self.spring_order].astype(npr))
            self.spring_kd.from_numpy(springs["damping"][self.spring_order].astype(npr))
        if self.grids:
            grid_cloths = [c for c in scene.cloths if c.is_grid and c.stencil]
            self.grids = [self._grid_block(c) for c in grid_cloths]
            self.grid_table.upload(self.grids)
        for feature in FEATURES:
            data = getattr(self, feature.name)
            if feature.live and data is not None:
                feature.refresh(data, getattr(scene, feature.name))
        self.colliders.upload(scene.colliders, colliders_off)

    def single_grid(self):
        """The GridBlock when the scene is one cloth grid and nothing else (no other
        particles or springs, no bending or membrane), else None."""
        if len(self.grids) == 1 and self.list_spring_count == 0 and self.bending is None \
                and self.membrane is None and self.grids[0].covers(self.particle_count):
            return self.grids[0]
        return None

    def state(self):
        """A new State with the scene's initial positions and velocities."""
        s = State(self.particle_count)
        npr = runtime.numpy_real()
        s.x.from_numpy(self.scene.positions.astype(npr))
        s.v.from_numpy(self.scene.velocities.astype(npr))
        return s
