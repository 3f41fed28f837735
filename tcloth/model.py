"""Model (static Taichi fields built once from a Scene) and State (per-step fields).

Pinned particles are ordinary particles with inverse mass 0. Springs live in one list
ordered so that the springs the force kernels walk one by one come first
(``list_spring_count`` of them); springs of cloths handled by the grid stencil follow and
are only read by diagnostics. Cloth grids are described by ``GridBlock`` records.
"""
from dataclasses import dataclass

import numpy as np
import taichi as ti

from . import colliders, runtime
from .errors import SceneError


@dataclass(frozen=True)
class GridBlock:
    """A regular cloth grid whose springs are evaluated by a neighbour stencil.

    offset: id of particle (i=0, j=0); ids run row by row (id = offset + j*nx + i).
    dx, dy: rest spacing (m). Each family is (k_s, k_d) or None.
    """
    offset: int
    nx: int
    ny: int
    dx: float
    dy: float
    structural: tuple
    shear: tuple
    flexion: tuple

    @property
    def families(self):
        """Static flags (structural, shear, flexion): which families exist."""
        return (self.structural is not None, self.shear is not None, self.flexion is not None)


def _vec_field(n):
    return ti.Vector.field(3, runtime.real(), shape=n)


class State:
    """Per-step particle state.

    Attributes:
        x: positions, shape (particle_count,) of vec3, m.
        v: velocities, shape (particle_count,) of vec3, m/s.
        f: force accumulator, shape (particle_count,) of vec3, N.
        forces_valid: True when ``f`` holds the forces at (x, v) (used by Verlet).
        t: the time of this state, s (moving colliders depend on it).
    """

    def __init__(self, n):
        self.x = _vec_field(n)
        self.v = _vec_field(n)
        self.f = _vec_field(n)
        self.forces_valid = False
        self.t = 0.0


class Model:
    """Static description of a scene as Taichi fields.

    Attributes:
        particle_count, spring_count, list_spring_count: sizes.
        mass, inv_mass: shape (particle_count,), kg and 1/kg (0 = pinned).
        spring_pairs: shape (spring_count,) of 2 x i32 particle ids.
        spring_rest, spring_ks, spring_kd: shape (spring_count,); m, N/m, N s/m.
        grids: list of GridBlock (empty when grid_stencil=False).
        wind: the scene's wind dict or None (None too without cloth triangles);
            triangles (triangle_count,) of 3 x i32 and wind_params (velocity (3),
            amplitude (3), frequency, phase, drag, lift, tangential) when set.
        attraction: (G, softening) or None.
        strain_limit: dict or None; limit_index: ids of the limited springs.
        collider_records: shape (collider_count,) rows of tcloth.colliders.RECORD numbers,
            sorted by kind; collider_ranges: static ((first, count) per kind).
        params: field (g_x, g_y, g_z, air_drag): m/s^2 and N s/m, read by the kernels.
        grid_ints, grid_reals: per GridBlock (offset, nx, ny) and
            (dx, dy, k_s x 3 families, k_d x 3 families) for the stencil kernel;
            grid_forces its scratch, (particle_count, 6) vec3; spring_grids: indices of
            the grids with springs; grid_sets_forces: the first of them holds every
            particle and sets gravity and drag with its springs.
    """

    def __init__(self, scene, grid_stencil=True):
        self.generation = runtime.ensure_init()
        self.scene = scene
        self.particle_count = n = scene.num_particles
        if n == 0:
            raise SceneError("scene has no particles (got num_particles = 0)")
        npr = runtime.numpy_real()
        real = runtime.real()
        # kernel parameters live in fields: vector kernel arguments cost ~40 us a launch
        self.params = ti.field(real, shape=4)
        self.params.from_numpy(np.array([*scene.gravity, scene.air_drag], dtype=npr))

        self.mass = ti.field(real, shape=n)
        self.inv_mass = ti.field(real, shape=n)
        m = scene.masses
        self.mass.from_numpy(m.astype(npr))
        self.inv_mass.from_numpy(np.where(scene.pinned, 0.0, 1.0 / m).astype(npr))

        springs = scene.springs
        in_grid = np.zeros(scene.num_springs, dtype=bool)
        self.grids = []
        if grid_stencil:
            for cloth in scene.cloths:
                for sids in cloth.springs.values():
                    in_grid[sids] = True
                p = cloth.params
                self.grids.append(GridBlock(cloth.offset, *cloth.resolution, *cloth.spacing,
                                            p["structural"], p["shear"], p["flexion"]))
        self.grid_ints = ti.Vector.field(3, ti.i32, shape=max(len(self.grids), 1))
        self.grid_reals = ti.Vector.field(8, real, shape=max(len(self.grids), 1))
        for k, g in enumerate(self.grids):
            fams = (g.structural, g.shear, g.flexion)
            self.grid_ints[k] = (g.offset, g.nx, g.ny)
            self.grid_reals[k] = [g.dx, g.dy] + [0.0 if p is None else p[c]
                                                 for c in (0, 1) for p in fams]
        # scratch of the grid stencil: the forces of the 6 springs each particle owns
        self.grid_forces = ti.Vector.field(3, real, shape=(n if self.grids else 1, 6))
        # the grids with springs; when the first holds every particle, its stencil kernel
        # also writes gravity and drag (one launch and one pass fewer)
        self.spring_grids = [k for k, g in enumerate(self.grids) if any(g.families)]
        first = self.grids[self.spring_grids[0]] if self.spring_grids else None
        self.grid_sets_forces = first is not None and first.offset == 0 and \
            first.nx * first.ny == n
        order = np.argsort(in_grid, kind="stable")
        self.spring_count = ns = scene.num_springs
        self.list_spring_count = int((~in_grid).sum())
        self.spring_pairs = ti.Vector.field(2, ti.i32, shape=max(ns, 1))
        self.spring_rest = ti.field(real, shape=max(ns, 1))
        self.spring_ks = ti.field(real, shape=max(ns, 1))
        self.spring_kd = ti.field(real, shape=max(ns, 1))
        if ns:
            self.spring_pairs.from_numpy(springs["pairs"][order].astype(np.int32))
            self.spring_rest.from_numpy(springs["rest_length"][order].astype(npr))
            self.spring_ks.from_numpy(springs["stiffness"][order].astype(npr))
            self.spring_kd.from_numpy(springs["damping"][order].astype(npr))

        self._build_wind_and_limits(scene, order, real, npr)
        rows, self.collider_ranges = colliders.pack(scene.colliders)
        self.collider_count = len(rows)
        self._adjacency = None
        self.collider_records = ti.Vector.field(colliders.RECORD, real,
                                                shape=max(self.collider_count, 1))
        if self.collider_count:
            self.collider_records.from_numpy(rows.astype(npr))

    def _build_wind_and_limits(self, scene, order, real, npr):
        tris = [c.triangles for c in scene.cloths]
        self.wind = scene.wind if scene.wind is not None and tris else None
        if self.wind is not None:
            t = np.concatenate(tris)
            self.triangle_count = len(t)
            self.triangles = ti.Vector.field(3, ti.i32, shape=len(t))
            self.triangles.from_numpy(t.astype(np.int32))
            w = self.wind
            self.wind_params = ti.field(real, shape=11)
            self.wind_array = np.array(
                [*w["velocity"], *w["amplitude"], w["frequency"], w["phase"], w["drag"],
                 w["lift"], w["tangential"]], dtype=npr)
            self.wind_params.from_numpy(self.wind_array)
        self.attraction = scene.attraction
        self.strain_limit = scene.strain_limit
        if self.strain_limit is not None:
            position = np.empty(len(order), dtype=np.int64)
            position[order] = np.arange(len(order))      # scene spring id -> model row
            idx = position[self.strain_limit["springs"]].astype(np.int32)
            self.limit_count = len(idx)
            self.limit_index = ti.field(ti.i32, shape=max(len(idx), 1))
            if len(idx):
                self.limit_index.from_numpy(idx)
            self.limit_dx = ti.Vector.field(3, real, shape=self.particle_count)
            self.limit_hits = ti.field(ti.i32, shape=self.particle_count)
            self.limit_x0 = ti.Vector.field(3, real, shape=self.particle_count)

    def adjacency(self):
        """The springs at each particle, for per-particle gathers (built on first use).

        Returns (start, adj): the entries of particle p are adj[start[p]:start[p + 1]],
        each (spring row, other particle id); every spring appears at both its ends.
        """
        if self._adjacency is None:
            pairs = self.spring_pairs.to_numpy()[:self.spring_count].astype(np.int64)
            ends = np.concatenate([pairs[:, 0], pairs[:, 1]])
            rows = np.tile(np.arange(self.spring_count), 2)
            others = np.concatenate([pairs[:, 1], pairs[:, 0]])
            order = np.argsort(ends, kind="stable")
            start = np.zeros(self.particle_count + 1, dtype=np.int32)
            np.cumsum(np.bincount(ends, minlength=self.particle_count), out=start[1:])
            adj = ti.Vector.field(2, ti.i32, shape=max(len(ends), 1))
            if len(ends):
                adj.from_numpy(np.stack([rows[order], others[order]], axis=1).astype(np.int32))
            first = ti.field(ti.i32, shape=self.particle_count + 1)
            first.from_numpy(start)
            self._adjacency = (first, adj)
        return self._adjacency

    def state(self):
        """A new State with the scene's initial positions and velocities."""
        s = State(self.particle_count)
        npr = runtime.numpy_real()
        s.x.from_numpy(self.scene.positions.astype(npr))
        s.v.from_numpy(self.scene.velocities.astype(npr))
        return s
