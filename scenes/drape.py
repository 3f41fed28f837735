"""Cusick's drape test: a 30 cm disc of fabric, clamped at its centre between two 18 cm
discs, hangs into folds.

Its drape coefficient is the shadow's share of the ring outside the support
(``tools/drape.py`` measures it for the fabric presets).

    tcloth render scenes/drape.py --set fabric=denim --out out/drape.mp4
    tcloth view scenes/drape.py --set fabric=fleece

Defaults: backward Euler at one step per 1/60 s frame with up to 50 Newton iterations:
the drape coefficient is a measurement (``tools/drape.py``), so the step is solved to
convergence on the fabric's stiff membrane. Not real time: 59 wall s per simulated s on
two cores, nearly all of it conjugate-gradient iterations of the membrane's and
bending's products (``python tools/bench_scenes.py --scenes drape``)."""
import numpy as np

import tcloth
from tcloth.scene.fabric import preset
from tcloth.geometry.primitives import disc
from tcloth.validate import as_int, as_scalar

CONFIG = {
    "integrator": "backward_euler",
    "options": {"newton_iterations": 50},
    "dt": 1 / 60,
    "steps_per_frame": 1,
    "frames": 150,
    "camera": {"eye": (0.38, 0.5, 0.45), "target": (0.0, 0.2, 0.0), "fov": 40.0},
}


def build(fabric="denim", rings=24, radius=0.15, support=0.09, height=0.3):
    """The specimen (a disc mesh of ``rings`` rings of a preset's name or a Fabric, warp
    along x, with the mean of its warp and weft bending: a mesh's hinges take one) on its
    support, a cylinder of radius ``support``; the particles within the support's radius
    are clamped (pinned)."""
    rings = as_int("rings", rings, 1)
    radius = as_scalar("radius", radius, minimum=0.0, strict=True)
    support = as_scalar("support", support, minimum=0.0, strict=True)
    if support >= radius:
        raise tcloth.SceneError(f"support must be less than radius {radius:g} m (got "
                                f"{support:g}): the disc must reach past its support")
    height = as_scalar("height", height, minimum=0.01, strict=True)    # the support's 1 cm gap
    vertices, triangles = disc(rings, radius)
    vertices[:, 1] += height
    clamped = np.flatnonzero(np.hypot(vertices[:, 0], vertices[:, 2]) <= support + 1e-9)
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_drag=1e-4)
    scene.add_mesh_cloth(vertices, [tuple(t) for t in triangles.tolist()], pinned=clamped,
                         fabric=preset(fabric).mean_bending())
    scene.add_cylinder(center=(0.0, 0.5 * (height - 0.01), 0.0), radius=support,
                       half_height=0.5 * (height - 0.01), thickness=0.002)
    scene.add_plane(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0))
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
