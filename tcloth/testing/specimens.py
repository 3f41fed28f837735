"""A textile lab's specimens of one fabric in one scene, and their measurements as losses
(``tcloth.grad``): Peirce's cantilever (a strip along the warp and one along the weft,
each at two overhang lengths: the chord angle to the tip edge), Cusick's drape (the drape
coefficient of a 30 cm disc on an 18 cm support) and a bias extension (a 5 x 15 cm strip
cut at 45 degrees to the warp, clamped at its top edge, a 100 g bar at its bottom edge: how
far the bar hangs below the strip's length). tools/fit_fabric.py fits a fabric to them and
argues each specimen's size.
"""
import numpy as np

import tcloth
from tcloth import grad
from tcloth.geometry.primitives import disc, grid_triangles
from tcloth.scene.fabric import Fabric

# the strips, m: Peirce's width (ASTM D1388, BS 3356: 2.5 cm); overhangs whose chord angles
# (denim's 25-50 degrees) bracket Peirce's 41.5, where the angle moves most with B; at 5 cm
# they hung at 61-72 degrees
WIDTH, LENGTHS = 0.025, (0.03, 0.04)
# the strips' points across: the mean of the tip edge's 8 takes 1 mm of noise a point down
# to 0.35 mm; cells 3.6 mm across, 2.1 to 2.8 mm along at 16 cells
ACROSS = 8
RADIUS, SUPPORT, HEIGHT = 0.15, 0.09, 0.3   # the drape: m
BIAS_WIDTH, BIAS_LENGTH, BIAS_LOAD = 0.05, 0.15, 0.1    # the bias strip: m, m, kg
BIAS_GRID = (6, 16)                         # its vertices across and along
SCALE_ANGLE, SCALE_DC, SCALE_EXT = 1.0, 0.01, 1.0       # the loss's units: 1 degree, 0.01, 1 mm

def add_disc(scene, fabric, rings):
    """Cusick's disc of ``fabric`` (a mesh cloth of ``rings`` rings, the mean of its warp
    and weft bending) clamped within the support's radius, flat at the support's height;
    its rim's particle ids in angular order."""
    vertices, triangles = disc(rings, RADIUS)
    vertices[:, 1] += HEIGHT
    clamped = np.flatnonzero(np.hypot(vertices[:, 0], vertices[:, 2]) <= SUPPORT + 1e-9)
    offset = scene.num_particles
    scene.add_mesh_cloth(vertices, [tuple(t) for t in triangles.tolist()], pinned=clamped,
                         fabric=fabric.mean_bending())
    rim = np.flatnonzero(np.hypot(vertices[:, 0], vertices[:, 2]) > RADIUS - 1e-9)
    return offset + rim[np.argsort(np.arctan2(vertices[rim, 2], vertices[rim, 0]))]


class Specimens:
    """The six specimens of one fabric in one scene, and their measurements."""

    def __init__(self, fabric, cells, rings):
        self.scene = scene = tcloth.Scene(air_drag=1e-4)
        self.strips = []            # (cloth, family, clamp particle, tip edge particles)
        for s, (length, family) in enumerate([(l, f) for f in (0, 1) for l in LENGTHS]):
            self.strips.append(self._strip(scene, fabric, length, family, cells,
                                           origin=(0.3 + 0.25 * s, 1.0, 0.0)))
        self.rim = add_disc(scene, fabric, rings)
        self.hanging = scene.positions
        self.top, self.bottom = self._bias(scene, fabric.mean_bending(),
                                           origin=(-0.4, 1.0, 0.0))
        self.rigidity = np.array(scene.bending["rigidity"], dtype=np.float64)

    def _bias(self, scene, fabric, origin):
        """The bias strip hanging from its clamp at ``origin`` (its top edge's middle,
        across x, down -y), added turned by 45 degrees about z (its rest shape, where the
        membrane takes its warp along x), its hanging positions kept in ``hanging``; the
        load shared by its bottom edge. Returns (clamp, bottom edge) particle ids."""
        across, along = BIAS_GRID
        u, w = np.meshgrid(np.linspace(0.0, BIAS_LENGTH, along),
                           np.linspace(-BIAS_WIDTH / 2, BIAS_WIDTH / 2, across), indexing="ij")
        hang = np.asarray(origin) + np.stack([w.ravel(), -u.ravel(), np.zeros(u.size)], 1)
        c = np.sqrt(0.5)
        turn = np.array([[c, -c, 0.0], [c, c, 0.0], [0.0, 0.0, 1.0]])
        offset = scene.num_particles
        top = offset + np.arange(across)
        scene.add_mesh_cloth((hang - origin) @ turn.T + origin,
                             [tuple(t) for t in grid_triangles(along - 1, across - 1).tolist()],
                             pinned=top - offset, fabric=fabric)
        self.hanging = np.concatenate([self.hanging, hang])
        bottom = offset + (along - 1) * across + np.arange(across)
        masses = scene.masses
        masses[bottom] += BIAS_LOAD / across
        scene.set_masses(masses)
        return top, bottom

    @staticmethod
    def _strip(scene, fabric, length, family, cells, origin):
        """A strip along the warp (family 0: along x) or the weft (1: along z), ``cells``
        points along and ACROSS across WIDTH, clamped over its first two columns (every
        point across); the clamp line half a cell inside them. Returns (cloth, family, a
        particle of the second clamped column, the tip edge's particles): the chord angle
        takes its run along the strip, the same from every point of that column."""
        dx = length / (cells - 1.5)
        size = (cells - 1) * dx
        strip = Fabric(density=fabric.density, stretch=2000.0, shear=5.0,
                       bending=fabric.bending)
        x0, y0, z0 = origin
        clamp = [(i, j) for i in (0, 1) for j in range(ACROSS)]
        if family == 0:
            resolution, extent, center = (cells, ACROSS), (size, WIDTH), (x0 + size / 2, y0, z0)
        else:
            resolution, extent, center = (ACROSS, cells), (WIDTH, size), (x0, y0, z0 + size / 2)
            clamp = [(j, i) for i, j in clamp]
        cloth = scene.add_cloth(resolution=resolution, size=extent, center=center,
                                fabric=strip, pinned=clamp)
        p = cloth.particles
        column = p[:, 1] if family == 0 else p[1, :]        # the second clamped column
        edge = p[:, -1] if family == 0 else p[-1, :]        # the tip's edge across the strip
        return len(scene.cloths) - 1, family, column[0], np.asarray(edge)

    def measures(self, steps, targets=None):
        """The six measurements as losses at ``steps`` against ``targets`` (default 0;
        each in its unit: 1 degree, 0.01 of drape coefficient, 1 mm): the strips' chord
        angles, the drape coefficient, the bias extension."""
        targets = np.zeros(6) if targets is None else targets
        angles = [grad.ChordAngle(clamp, edge, 0 if family == 0 else 2, steps, target,
                                  SCALE_ANGLE)
                  for (_, family, clamp, edge), target in zip(self.strips, targets)]
        return angles + [
            grad.DrapeCoefficient(self.rim, RADIUS, SUPPORT, steps, targets[4], SCALE_DC),
            BiasExtension(self.top, self.bottom, steps, targets[5], SCALE_EXT)]

    def measure(self, x):
        return np.array([m.measure(x)[0] for m in self.measures(0)])


class BiasExtension(grad.Measured):
    """The bias strip's extension: its bottom edge's mean below its clamp line's, less
    its length, mm."""

    def __init__(self, top, bottom, steps, target, scale):
        super().__init__(steps, target, scale)
        self.top, self.bottom = top, bottom

    def measure(self, x):
        value = 1e3 * (x[self.top, 1].mean() - x[self.bottom, 1].mean() - BIAS_LENGTH)
        g = np.zeros_like(x)
        g[self.top, 1] = 1e3 / len(self.top)
        g[self.bottom, 1] = -1e3 / len(self.bottom)
        return value, g
