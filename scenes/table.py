"""A tablecloth falls onto a table read from an OBJ mesh and drapes over its raised rim.

The table, scenes/assets/table.obj (tools/make_table_obj.py writes it), is a mesh collider:
a 1.2 x 0.8 m top at 0.75 m with a lip 1.5 cm high round its edge, on four legs. The cloth,
1.6 x 1.2 m, overhangs each side by 20 cm.

Defaults: XPBD at one step per 1/30 s frame, 3 iterations a substep (37 automatic
substeps). Against symplectic Euler at dt = 2e-4 s (the reference), after 1.5 s its
particles lie 6.1 mm RMS away, projective dynamics' at one step per 1/60 s (the earlier
default) 20.5 mm, XPBD's with its default 10 iterations 12.7 mm; resting at 2 s, its
most stretched structural spring is 4.3 % long, the reference's 2.4 %, projective's 2.1
% and XPBD's with 10 iterations 8.8 % (fewer substeps of more iterations converge less).
It costs about half of projective dynamics: 1.6 wall s per simulated s on two cores
where projective took 3.0 in the same run (``python tools/bench_scenes.py --scenes
table``; ``--config integrator=projective --config dt=1/60 --config options={}`` for the
other). The table is a distance field (docs/mesh_colliders.md), queried inside every
substep."""
import os
import sys

import tcloth

CONFIG = {
    "integrator": "xpbd",
    "options": {"iterations": 3},
    "dt": 1 / 30,
    "steps_per_frame": 1,
    "frames": 90,
    "camera": {"eye": (1.35, 1.45, 1.75), "target": (0.0, 0.6, 0.0), "fov": 40.0},
}
ASSET = os.path.join(os.path.dirname(os.path.abspath(__file__)), "assets", "table.obj")


def write_asset(path=ASSET):
    """Write the table as the OBJ this scene reads (tools/make_table_obj.py)."""
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tools"))
    import make_table_obj
    make_table_obj.main(["--out", path])


def build(mesh=ASSET, resolution=(64, 48), size=(1.6, 1.2), drop=0.1, friction=0.4):
    if not os.path.exists(mesh):
        write_asset(mesh)
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0), air_drag=2e-4)
    scene.add_cloth(resolution=resolution, size=size, center=(0.0, 0.765 + drop, 0.0),
                    plane="xz", mass=0.35, structural=(400.0, 0.05), shear=(80.0, 0.02),
                    flexion=(4.0, 0.004), pinned=[])
    scene.add_mesh_collider(mesh, friction=friction)
    scene.add_plane(point=(0.0, 0.0, 0.0), normal=(0.0, 1.0, 0.0), friction=0.5)
    return scene


if __name__ == "__main__":
    tcloth.cli.run_script(__file__)
