"""A blanket settles over a sleeping body whose chest rises and falls, and breathes with it.

The body is a deforming mesh collider made here with NumPy: an ellipsoid lying along x
on the floor (an icosphere stretched), whose upper half swells by up to ``swell`` (m) at
the chest once every ``period`` seconds (``deform``, a callable of time giving the
vertices in the mesh's own frame); its underside stays on the floor. The head is a
sphere; the blanket covers the chest and leaves the body's ends out.

Defaults: projective dynamics at one step per 1/60 s frame with 5 iterations a step, not
its default 10: resting at 2 s the most stretched structural spring is 2.4 % long, 2.2 %
with 10 iterations (peaks over the landing 4.6 % and 3.3 %), at 0.66 of the cost
(resting, 0.47) (``python tools/bench_scenes.py --scenes breathing``, and ``--config
options={'iterations':10}``). The body deforms, so it is met through the certified mesh
pairs rather than a distance field (which would be baked again every step), its
hierarchy refit and its pseudo normals recomputed each step. Not yet real time: 2.5 wall
s per simulated s on two cores."""
import numpy as np

import tcloth
from tcloth.geometry.primitives import icosphere

CONFIG = {
    "integrator": "projective",
    "options": {"iterations": 5},
    "dt": 1 / 60,
    "steps_per_frame": 1,
    "frames": 240,
    "camera": {"eye": (0.6, 0.7, 1.2), "target": (0.05, 0.15, 0.0), "fov": 45.0},
}
RADII = (0.45, 0.16, 0.2)     # m: the body's half length (x), height (y), half width (z)
HEAD = 0.11                   # m: the head's radius


def body(subdivisions=4, radii=RADII):
    """(vertices, triangles) of the body at rest: its lowest point at y = 0."""
    v, tri = icosphere(1.0, subdivisions)
    return v * radii + (0.0, radii[1], 0.0), tri


def breathing(rest, swell=0.05, period=3.0):
    """deform(t) -> (V, 3) vertices: each vertex above the middle height raised in
    proportion to its height there, most at the chest (x = 0), by up to ``swell`` at
    full breath (a breath every ``period`` s, starting from rest)."""
    middle = 0.5 * (rest[:, 1].max() + rest[:, 1].min())
    half_height = rest[:, 1].max() - middle
    length = np.abs(rest[:, 0]).max()
    upper = np.clip((rest[:, 1] - middle) / half_height, 0.0, None)
    chest = np.cos(0.5 * np.pi * rest[:, 0] / length) ** 2
    lift = swell * upper * chest

    def deform(t):
        out = rest.copy()
        out[:, 1] += lift * 0.5 * (1.0 - np.cos(2.0 * np.pi * t / period))
        return out
    return deform


def build(resolution=(30, 44), size=(0.6, 0.9), drop=0.1, swell=0.05, period=3.0,
          friction=0.5):
    rest, tri = body()
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_drag=2e-4)
    scene.add_cloth(resolution=resolution, size=size,
                    center=(0.0, 2 * RADII[1] + drop, 0.0), plane="xz", mass=0.3,
                    structural=(300.0, 0.05), shear=(60.0, 0.02), flexion=(2.0, 0.003),
                    pinned=[])
    scene.add_mesh_collider((rest, tri), friction=friction,
                            deform=breathing(rest, swell, period))
    scene.add_sphere(center=(RADII[0] + 0.8 * HEAD, HEAD, 0.0), radius=HEAD,
                     friction=friction)
    scene.add_plane(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), friction=0.5)
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
