"""What the renderer draws besides cloth triangles and colliders, and in which colours:
spheres for free particles and beads along springs between them (ropes), and the
front and back colours of each cloth. Plain NumPy from the scene, made once per
Renderer."""
import numpy as np

from .errors import SceneError

FRONT_COLOUR = (0.85, 0.28, 0.18)
BACK_COLOUR = (0.20, 0.42, 0.80)


def cloth_palette(cloth_colours, cloths):
    """(cloths, 2, 3) front and back RGB per cloth: the defaults, or ``cloth_colours``
    checked (one (front, back) pair of values in [0, 1] per cloth)."""
    palette = np.array(cloth_colours if cloth_colours is not None else
                       [(FRONT_COLOUR, BACK_COLOUR)] * cloths, dtype=np.float64)
    if palette.size == 0:
        palette = palette.reshape(0, 2, 3)
    if palette.shape != (cloths, 2, 3) or not np.all((palette >= 0) & (palette <= 1)):
        raise SceneError(f"cloth_colours must hold one (front, back) pair of RGB values in "
                         f"[0, 1] per cloth ({cloths} cloths; got {cloth_colours!r})")
    return palette


def particle_spheres(scene, particle_radius, extent):
    """(spheres (S, 3): end particle i, end particle j, fraction s along i -> j; radius).

    Every particle outside a cloth is a sphere (i = j, s = 0); each spring between two
    such particles gets beads spaced about one radius apart at its initial length.
    particle_radius None picks 0.35 times the median rest length of those springs, or
    2 % of the scene's extent without them."""
    x0 = scene.positions
    in_cloth = np.zeros(scene.num_particles, dtype=bool)
    for c in scene.cloths:
        in_cloth[c.particles.ravel()] = True
    free = np.flatnonzero(~in_cloth)
    sp = scene.springs
    free_spring = ~in_cloth[sp["pairs"][:, 0]] & ~in_cloth[sp["pairs"][:, 1]]
    line = sp["pairs"][free_spring]
    if particle_radius is None:
        rest = sp["rest_length"][free_spring]
        particle_radius = 0.35 * float(np.median(rest)) if len(rest) else 0.02 * extent
    radius = float(particle_radius)
    beads = [np.stack([np.full(k, i), np.full(k, j), (np.arange(k) + 1) / (k + 1)], 1)
             for (i, j), k in zip(line, np.ceil(np.linalg.norm(
                 x0[line[:, 0]] - x0[line[:, 1]], axis=1) / radius).astype(int))]
    spheres = np.concatenate([np.stack([free, free, np.zeros(len(free))], 1)] + beads)
    return spheres, radius
