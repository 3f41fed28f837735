"""The mesh-collider drape of tools/bench_mesh_collider.py in Newton (``pip install
newton``), for a side-by-side run: a cloth dropped onto a triangle-mesh sphere, SolverVBD
on the CPU.

Run with a Python that has newton (it needs numpy >= 2, so a venv of its own is
simplest); the benchmark calls it and reads the .npz it writes, then counts the crossings
and the particles inside the sphere at the end with tcloth.testing.crossings (NumPy only):
``python tools/crossings.py result.npz`` prints them too.

The scene is tcloth's ``add_cloth(resolution=(64, 64), size=(1.2, 1.2), plane="xz",
center=(0, 1, 0), mass=0.2, pinned=[])`` with springs structural (400, 0.5), shear
(80, 0.25), flexion (10, 0.05) ((k_s N/m, k_d N s/m); Newton's ``add_spring`` takes the
same k_s and an axial damping k_d in N s/m): particle (i, j) at x = i h - 0.6, y = 1,
z = j h - 0.6, index j n + i, none pinned, gravity -9.81 along y. The obstacle is
``tcloth/testing/meshes.py``'s ``sphere_mesh(0.35, --triangles, center=(0, 0.35, 0))``, the same
triangles tcloth's benchmark collides with, a static ``add_shape_mesh`` (body -1). No
triangle membrane or dihedral bending (Newton's cloth usually has them; here only the
springs, as tcloth), self-contact off, the (i mod 3, j mod 3) spring colouring of
tools/newton_peer.py.

Contact, as close to tcloth's collider defaults as Newton allows (tcloth: penalty k =
1000 N/m, damping 0.5 of critical per particle, offset ``thickness`` 5 mm, mu 0):
- each particle has radius 0.005 m (Newton's contact offset); the shape's margin is 0;
- the penalty ke = 1000 N/m and the approach damping kd = 2 x 0.5 x sqrt(ke m) N s/m
  (0.221 for m = 0.2/4096 kg) are set both on the model (``soft_contact_ke/kd/mu``) and on
  the shape, since Newton averages the two;
- Newton's particle-shape contact is per particle (a particle against the mesh's closest
  point, found within radius + gap of the surface when detection runs, at the start of
  each step here): no cloth-edge against mesh-edge contact, and no guarantee against
  crossings, where tcloth's contact stage has both. ``--gap`` (default 0.05 m, Newton's
  own default is 0.01) must cover a step's travel (the cloth meets the sphere at about
  2.4 m/s, 4 cm a step at 1/60 s): a particle that starts a step within the gap is
  pushed out; one that ends deeper than the gap is lost inside.
- ``--full-surface`` turns on Newton's full-surface rigid-soft contacts (cloth edges and
  faces against the mesh's features too; their records need ``--soft-contact-max``,
  1,000,000 by default with it, where Newton's own estimate overflows). ``--analytic``
  collides with Newton's analytic sphere shape of the same radius instead of the mesh
  (the reference for the mesh's cost and behaviour).
- tcloth's contact law adds Coulomb friction with a regularisation speed; Newton's VBD
  has its own smoothed friction (``friction_epsilon``); with mu = 0 neither acts.

Measured (Newton 1.8.0, two CPU cores): at dt = 1/60 and 10 iterations VBD does not
converge on these springs (k dt^2 / m is about 2,300 for a structural spring): where the
cloth hangs it stretches several-fold, and its weight pulls it through the sphere, the
mesh and the analytic sphere alike, so that at 1 s it lies below the sphere. At
dt = 1/600 (``--dt 0.0016667 --steps 600``) the same scene drapes with no crossing.

Usage: python tools/newton_mesh_peer.py --triangles 10000 --steps 60 --dt 0.0166667
                                        --iterations 10 --out result.npz
The .npz holds step_times (s, every step but the first, a warm-up in which Warp compiles
or loads its kernels), positions (the particles at the end, float64), triangles (the
cloth's, as tcloth's grid splits its quads), obstacle_vertices, obstacle_triangles, a
JSON summary and, with ``--trajectory``, every step's positions (steps, N, 3) float32.
"""
import argparse
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from newton_peer import add_grid_springs, numpy_reference, timed_steps  # noqa: E402

sphere_mesh = numpy_reference("meshes").sphere_mesh
N = 64
SIZE = 1.2
HEIGHT = 1.0
RADIUS = 0.35
CENTRE = (0.0, 0.35, 0.0)
FAMILIES = {"structural": ([(1, 0), (0, 1)], 400.0, 0.5),
            "shear": ([(1, 1), (-1, 1)], 80.0, 0.25),
            "flexion": ([(2, 0), (0, 2)], 10.0, 0.05)}
CONTACT_KE = 1000.0
THICKNESS = 0.005


def cloth_grid(n, size, height):
    """(n n, 3) positions of the flat cloth and its (2 (n-1)^2, 3) triangles, as tcloth's
    ``add_cloth(plane="xz")`` lays them out: quad (a, b, c, d) = ((i, j), (i+1, j),
    (i+1, j+1), (i, j+1)) split into (a, d, b) and (b, d, c)."""
    h = size / (n - 1)
    ii, jj = np.meshgrid(np.arange(n), np.arange(n))
    x = np.stack([ii * h - size / 2, np.full(ii.shape, height), jj * h - size / 2], -1)
    p = np.arange(n * n).reshape(n, n)
    a, b, c, d = p[:-1, :-1], p[:-1, 1:], p[1:, 1:], p[1:, :-1]
    triangles = np.concatenate([np.stack([a, d, b], -1).reshape(-1, 3),
                                np.stack([b, d, c], -1).reshape(-1, 3)])
    return x.reshape(-1, 3), triangles


def build(args, vertices, faces):
    """The Newton model: the cloth's particles and springs and the static sphere mesh."""
    import newton
    particle_mass = args.mass / (N * N)
    kd = 2.0 * 0.5 * np.sqrt(CONTACT_KE * particle_mass)
    builder = newton.ModelBuilder(up_axis=newton.Axis.Y, gravity=(0.0, -9.81, 0.0))
    x, _ = cloth_grid(N, SIZE, HEIGHT)
    builder.add_particles(x.tolist(), [(0.0, 0.0, 0.0)] * (N * N),
                          mass=[particle_mass] * (N * N), radius=[THICKNESS] * (N * N),
                          flags=[int(newton.ParticleFlags.ACTIVE)] * (N * N))
    add_grid_springs(builder, N, FAMILIES)
    cfg = newton.ModelBuilder.ShapeConfig(ke=CONTACT_KE, kd=kd, mu=args.friction, margin=0.0)
    if args.analytic:
        import warp as wp
        builder.add_shape_sphere(-1, xform=wp.transform(wp.vec3(*CENTRE), wp.quat_identity()),
                                 radius=RADIUS, cfg=cfg)
    else:
        mesh = newton.Mesh(vertices, faces.ravel(), compute_inertia=False)
        builder.add_shape_mesh(-1, mesh=mesh, cfg=cfg)
    model = builder.finalize(device=args.device)
    model.soft_contact_ke, model.soft_contact_kd = CONTACT_KE, kd
    model.soft_contact_mu = args.friction
    return model, kd


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--triangles", type=int, default=10000)
    ap.add_argument("--steps", type=int, default=60)
    ap.add_argument("--dt", type=float, default=1.0 / 60.0)
    ap.add_argument("--iterations", type=int, default=10)
    ap.add_argument("--mass", type=float, default=0.2)
    ap.add_argument("--friction", type=float, default=0.0)
    ap.add_argument("--gap", type=float, default=0.05)
    ap.add_argument("--full-surface", action="store_true")
    ap.add_argument("--soft-contact-max", type=int, default=None)
    ap.add_argument("--analytic", action="store_true")
    ap.add_argument("--trajectory", action="store_true")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    import warp as wp
    import newton
    wp.init()
    vertices, faces = sphere_mesh(RADIUS, args.triangles, center=CENTRE)
    model, kd = build(args, vertices, faces)
    capacity = args.soft_contact_max or (1_000_000 if args.full_surface else None)
    pipeline = newton.CollisionPipeline(
        model, soft_contact_gap=args.gap, soft_contact_max=capacity,
        enable_rigid_soft_full_surface_contact=args.full_surface)
    solver = newton.solvers.SolverVBD(model, iterations=args.iterations,
                                      particle_enable_self_contact=False,
                                      collision_pipeline=pipeline)
    trajectory = []
    positions, times = timed_steps(model, solver, args.steps, args.dt,
                                   trajectory.append if args.trajectory else None)
    summary = {"newton": newton.__version__, "warp": wp.config.version, "solver": "vbd",
               "device": args.device, "iterations": args.iterations,
               "sphere_triangles": len(faces), "contact_ke": CONTACT_KE, "contact_kd": kd,
               "friction": args.friction, "gap": args.gap, "thickness": THICKNESS,
               "full_surface": args.full_surface, "analytic": args.analytic}
    np.savez(args.out, positions=positions, step_times=times,
             triangles=cloth_grid(N, SIZE, HEIGHT)[1], obstacle_vertices=vertices,
             obstacle_triangles=faces, summary=json.dumps(summary),
             trajectory=np.array(trajectory, dtype=np.float32).reshape(-1, N * N, 3))


if __name__ == "__main__":
    main()
