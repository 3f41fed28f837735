"""Physical fabric: areal density, membrane stiffnesses and bending rigidity, turned into a
cloth's particle masses, springs and hinge bending (docs/fabric.md derives the mapping).

A grid cloth's springs form a membrane. With cells dx x dy, structural springs k1 (along i,
the warp) and k2 (along j, the weft) and both diagonals k_d in every cell, the energy per
area at a uniform strain e is W = C11/2 e_xx^2 + C12 e_xx e_yy + C22/2 e_yy^2 + 2 C66 e_xy^2,

    C11 = k1 dx/dy + 2 k_d dx^3 / (L^2 dy),   C22 = k2 dy/dx + 2 k_d dy^3 / (L^2 dx),
    C12 = C66 = 2 k_d dx dy / L^2,            L^2 = dx^2 + dy^2,

so the shear stiffness G fixes k_d (C66 = G) and with it C12 = G (the lattice's Poisson
coupling), and the stretch stiffnesses (uniaxial, the sides free to contract: E1 = C11 -
C12^2 / C22, E2 = C22 - C12^2 / C11) fix k1, k2. Structural springs on the cloth's border
carry half a cell and get half the stiffness; each particle carries the fabric's density
times its share of the area (a quarter of each cell around it).

A mesh cloth has no springs: edge springs cannot hold a separate shear stiffness (Van
Gelder's 1998 stiffness k_e = E sum over the edge's triangles of A_t / |e|^2 gives an
equilateral mesh the uniaxial stiffness E with Poisson's ratio 1/3 and so shear 3E/8,
where fabric shears at a few percent of its stretch). Its triangles carry the fabric's
stretch (warp along the world x axis) and shear as a membrane (``terms/membrane.py``,
Poisson's ratio 0), and each particle an equal share of each face around it.

Damping is a ratio of critical per spring: k_d = zeta 2 sqrt(k_s m_i m_j / (m_i + m_j)),
and per membrane condition against the stiffer stretch (``terms/membrane.py``).
"""
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from ..validate import as_warp_weft, fmt


@dataclass(frozen=True)
class Fabric:
    """A fabric's physical parameters (SI units).

    Args:
        density: areal density, kg/m^2 > 0.
        stretch: uniaxial stretch stiffness per width, N/m > 0: a number or (warp, weft).
        shear: in-plane shear stiffness per width, N/m > 0.
        bending: bending rigidity per width, N m >= 0: a number or (warp, weft) (grid
            cloths; a mesh cloth takes one number).
        damping: the springs' and the membrane's damping as a ratio of critical, >= 0.
        name: what it is (presets).
        source: where its numbers were measured (presets).
    """
    density: float
    stretch: object
    shear: float
    bending: object
    damping: float = 0.1
    name: str = "custom"
    source: str = ""

    def __post_init__(self):
        object.__setattr__(self, "density", _number("density", self.density, "kg/m^2 > 0"))
        object.__setattr__(self, "stretch", as_warp_weft("stretch", self.stretch, strict=True))
        object.__setattr__(self, "shear", _number("shear", self.shear, "N/m > 0"))
        object.__setattr__(self, "bending", as_warp_weft("bending", self.bending))
        object.__setattr__(self, "damping", _number("damping", self.damping,
                                                    "a ratio of critical >= 0", strict=False))

    def without_bending(self):
        """This fabric with bending 0: the membrane alone, for a closed or curved mesh (a
        balloon), whose rest shape hinge bending cannot take (it needs a flat one)."""
        return Fabric(self.density, self.stretch, self.shear, 0.0, self.damping,
                      name=f"{self.name} (no bending)", source=self.source)

    def mean_bending(self):
        """This fabric with the geometric mean of its warp and weft bending (for a mesh
        cloth, whose hinges take one rigidity)."""
        return Fabric(self.density, self.stretch, self.shear,
                      float(np.sqrt(np.prod(self.bending))), self.damping,
                      name=f"{self.name} (mean bending)", source=self.source)

    def moduli(self):
        """(C11, C22, C12) N/m of the grid membrane with this fabric's stretch and shear
        (module docstring; they do not depend on the cell's shape)."""
        e1, e2 = self.stretch
        root = np.sqrt(1.0 + 4.0 * self.shear ** 2 / (e1 * e2))
        return 0.5 * e1 * (1.0 + root), 0.5 * e2 * (1.0 + root), self.shear

    def grid_stiffness(self, dx, dy):
        """(k1, k2, k_diagonal) N/m of an interior grid cell's springs."""
        c11, c22, g = self.moduli()
        diagonal = g * (dx * dx + dy * dy) / (2.0 * dx * dy)
        k1 = (c11 - g * dx * dx / (dy * dy)) * dy / dx
        k2 = (c22 - g * dy * dy / (dx * dx)) * dx / dy
        if k1 <= 0 or k2 <= 0:
            raise SceneError(f"a {dx:g} x {dy:g} m grid cannot hold shear {self.shear:g} N/m "
                             f"with stretch {self.stretch}: its diagonals alone would be "
                             "stiffer than that along the grid (lower the shear)")
        return k1, k2, diagonal


def _number(name, value, rule, strict=True):
    """A finite float > 0 (>= 0 unless ``strict``), or SceneError naming ``name``, the
    rule and the value."""
    try:
        x = float(value) if np.ndim(value) == 0 else np.nan
    except (TypeError, ValueError):
        x = np.nan
    if not (np.isfinite(x) and (x > 0 if strict else x >= 0)):
        raise SceneError(f"{name} must be {rule} (got {fmt(value)})")
    return x


def damping(fabric, ks, masses, pairs):
    """Each spring's k_d: the fabric's ratio of critical damping of its two masses."""
    mi, mj = masses[pairs[:, 0]], masses[pairs[:, 1]]
    return fabric.damping * 2.0 * np.sqrt(ks * mi * mj / (mi + mj))


def grid_masses(fabric, nx, ny, dx, dy):
    """(ny, nx) particle masses: density times a quarter of each cell around a particle."""
    wx = np.full(nx, dx)
    wx[[0, -1]] *= 0.5
    wy = np.full(ny, dy)
    wy[[0, -1]] *= 0.5
    return fabric.density * np.outer(wy, wx)


def grid_springs(fabric, cloth):
    """dict family -> (pairs (M,2), k_s (M,)) of a grid cloth: structural and shear (no
    flexion: the fabric bends through hinges)."""
    (nx, ny), (dx, dy) = cloth.resolution, cloth.spacing
    k1, k2, kd = fabric.grid_stiffness(dx, dy)
    row = np.repeat(np.arange(ny), nx - 1)            # grid_pairs: the springs along i,
    column = np.tile(np.arange(nx), ny - 1)           # then those along j, row by row
    ks_i = np.where((row == 0) | (row == ny - 1), 0.5 * k1, k1)
    ks_j = np.where((column == 0) | (column == nx - 1), 0.5 * k2, k2)
    shear = cloth.grid_pairs("shear")
    return {"structural": (cloth.grid_pairs("structural"), np.concatenate([ks_i, ks_j])),
            "shear": (shear, np.full(len(shear), kd))}


# Measured fabrics: Wang, O'Brien & Ramamoorthi 2011, "Data-driven elastic models for
# cloth: modeling and measurement", ACM TOG 30(4) 71, as published with ARCSim's material
# files (the data's u axis taken as the warp): density; stretch along u and v and shear at
# zero strain; bending at the smallest curvature, bending along u (a fold along v) and
# along v, converted to rigidities as docs/fabric.md says.
PRESETS = {
    "denim": Fabric(0.324, (411.0, 2028.0), 26.7, (2.42e-5, 1.60e-5), name="denim",
                    source="Wang et al. 2011, 11oz-black-denim"),
    "interlock": Fabric(0.187, (33.0, 69.0), 18.4, (3.6e-6, 5.8e-6), name="interlock",
                        source="Wang et al. 2011, gray-interlock (cotton/polyester knit)"),
    "ponte": Fabric(0.284, (62.0, 88.0), 15.9, (9.3e-6, 9.1e-6), name="ponte",
                    source="Wang et al. 2011, camel-ponte-roma (polyester/rayon knit)"),
    "polyester": Fabric(0.113, (86.0, 343.0), 7.2, (5.1e-6, 3.6e-6), name="polyester",
                        source="Wang et al. 2011, tango-red-jet-set (polyester)"),
    "fleece": Fabric(0.228, (303.0, 490.0), 15.1, (1.49e-5, 2.93e-5), name="fleece",
                     source="Wang et al. 2011, pink-ribbon-brown (polyester blanket)"),
}


def preset(name):
    """The preset fabric ``name`` (``PRESETS``); SceneError naming the known ones."""
    if isinstance(name, Fabric):
        return name
    if name not in PRESETS:
        raise SceneError(f"fabric must be a Fabric or one of {sorted(PRESETS)} (got {name!r})")
    return PRESETS[name]
