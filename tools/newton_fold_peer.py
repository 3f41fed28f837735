"""The self-contact fold of tools/bench_self_collision.py --implicit in Newton (``pip install
newton``), for a side-by-side run: its SolverVBD on the CPU, self-contact on and off.

Two halves, two Pythons. ``--export FILE.npz`` runs in tcloth's venv: it builds
scenes/fold.py at n x n as the bench does (``fold_scene``: thickness 6 mm x 40 / n), takes
the saved folded 40 x 40 state (tools/data/fold_40x40.npz) resampled bilinearly to n x n
(``resample``) and writes the particles (rest and folded positions, velocities, masses),
triangles, springs (pairs, rest lengths, k_s, k_d), colliders, gravity and the resolved
self-collision settings. ``--scene FILE.npz`` runs with a Python that has newton (it needs
numpy >= 2, so a venv of its own is simplest): it builds that scene in Newton and steps
``--steps`` steps of ``--dt`` (60 of 1/60 s: one simulated second) with SolverVBD at
``--iterations`` (10), self-contact on and off, from the same state. For each, one step of
a throwaway solver compiles or loads Warp's kernels first; then a fresh solver's steps are
all timed from the folded state (tcloth's bench also times its 60 steps after a warm-up,
from the same start). A step whose positions are not finite ends that run.

The model, as close to tcloth's as Newton allows:
- particles: tcloth's positions, velocities and masses (0.2 / n^2 kg each), none pinned;
  gravity -9.81 along y (``up_axis`` y).
- springs: tcloth's pairs, k_s and k_d (structural 400 / 0.05, shear 80 / 0.02, flexion
  10 / 0.005; Newton's ``add_spring`` takes the same k_s and an axial damping k_d in
  N s/m) with tcloth's rest lengths (from the flat grid, not the folded state).
- triangles and their edges: tcloth's triangles through ``add_cloth_mesh`` at the flat
  rest positions, with zero membrane and bending stiffness and damping (VBD skips such
  elements): they exist only for self-contact, which is point-triangle and edge-edge in
  both. The particles are then moved to the folded state (``builder.particle_q``/``qd``).
- colouring: (i mod 3, j mod 3), nine colours (``builder.color()`` reads no springs); no
  spring, triangle or hinge joins two particles whose offset is 0 mod 3 in both
  coordinates (checked for the springs).
- self-contact: ``particle_self_contact_margin`` = tcloth's thickness T (3.75 mm at 64):
  Newton's margin is the distance at which a vertex-triangle or edge-edge pair starts to
  repel, and tcloth's thickness is the distance its penalty keeps pairs apart, so the
  two laws are the same k/2 (T - d)^2 for T/2 < d < T; below T/2 Newton switches to a log
  barrier, where tcloth keeps the penalty and adds its guard (separating planes, no
  crossing at any step). ``particle_self_contact_gap`` (detection beyond the margin) =
  tcloth's skin (the thickness). k = tcloth's resolved stiffness (the mean structural,
  400 N/m); mu = 0.3; damping 0.1 of critical as an absolute kd = 2 x 0.1 x sqrt(k m_p / 2)
  (Newton's kd is per contact in N s/m, on the approach only; tcloth's uses each pair's
  effective mass); friction regularisation ``friction_epsilon`` = tcloth's stick
  velocity, 1e-3 m/s. Excluded pairs: Newton's topological filter at 2 rings (the
  default) drops a vertex and the triangles incident to its mesh neighbours, and edges
  incident to either edge's neighbours: tcloth's rule (a shared particle, or a particle
  of one a mesh neighbour of a particle of the other). Detection: Newton's default
  schedule (before and after the step's initialisation) with its own displacement
  truncation (DAT).
- colliders: the rod (a box, ``add_shape_box``) and the floor (``add_shape_plane``), each
  particle a radius of tcloth's collider thickness (5 mm, Newton's contact offset; shape
  margin 0), detected within ``--gap`` (0.05 m) once a step. Newton's particle-shape
  contact uses the mean of the model's ``soft_contact_ke``/``kd`` (which are also the
  self-contact's) and the shape's, and the geometric mean of the two mu: each shape's
  material is set so that the mix is tcloth's collider law (k 1000 N/m, kd = 2 x 0.5 x
  sqrt(k m_p), mu 0.8 on the rod and 0.6 on the floor). Particle-shape contact is per
  particle in Newton; tcloth's colliders also see edges and faces and guarantee no entry.
- not in Newton: tcloth's air damping (-1.6 m_p v on each particle; Newton's VBD has no
  mass-proportional drag), its Chebyshev acceleration (rho 0.9) and adaptive initial guess
  (Newton starts from x + h v + h^2 g). Neither has a membrane or dihedral bending here.

Prints, per mode, ``newton_fold.<n>x<n>.vbd.<mode>_wall_s`` (the timed steps' wall
seconds), ``_s_per_sim_s``, ``_steps``, ``_mean_height_m`` (the particles' mean height at
the end), ``_max_strain`` (the largest spring strain (length - rest) / rest after any
step) and ``_max_speed_mps``; ``_torn_at_step``, the first step past tcloth's default
strain_bound (1: twice the rest length), where there is one (Newton goes on stepping; a
torn cloth's numbers are no simulation), else ``_crossings`` (tools/crossings.py at the
end); and ``.ratio`` (on over off). ``--out`` gets the same as JSON (``summary``), each
run's step_times and end positions.

Measured beside tcloth's solvers on the same fold: docs/contact.md, "The fold beside
Newton's VBD".

Usage: python tools/newton_fold_peer.py --export /tmp/fold64.npz --n 64     (tcloth's venv)
       NEWTON_PYTHON tools/newton_fold_peer.py --scene /tmp/fold64.npz --out result.npz
                     [--steps 60] [--dt 0.0166667] [--iterations 10] [--gap 0.05]
                     [--modes on,off] [--device cpu]
"""
import argparse
import json
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from newton_peer import grid_colouring, numpy_reference  # noqa: E402
# tcloth's default strain_bound: (length - rest) / rest beyond it is a torn cloth
STRAIN_BOUND = 1.0
UNMAPPED = ("bending", "membrane", "strain_limit", "pressure", "wind", "attraction")


def jsonable(value):
    """``value`` with NumPy arrays and scalars as lists and floats, for JSON."""
    if isinstance(value, dict):
        return {key: jsonable(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(item) for item in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def export(path, n, state):
    """Write tcloth's fold at n x n and its folded state, as the bench builds them, to
    ``path`` (tcloth's venv)."""
    import tcloth
    from tcloth.app.script import load_script
    from tcloth.contact.topology import resolve
    from tcloth.testing.folding import fold_scene, folded_state, resample
    tcloth.init(arch="cpu", precision="f32")   # folded_state steps tcloth without the file
    module = load_script(os.path.join(HERE, "..", "scenes", "fold.py"))[0]
    x40, v40 = folded_state(module, state)
    scene = fold_scene(module, n)
    unmapped = [name for name in UNMAPPED if getattr(scene, name) is not None]
    if unmapped:
        raise SystemExit(f"the scene has {', '.join(unmapped)}, which this tool does not map")
    springs = scene.springs
    meta = {"n": n, "gravity": scene.gravity, "air_damping": scene.air_damping,
            "air_drag": scene.air_drag, "self_collision": resolve(scene),
            "colliders": scene.colliders}
    np.savez(path, rest_positions=scene.positions, positions=resample(x40, n),
             velocities=resample(v40, n), masses=scene.masses, triangles=scene.triangles,
             spring_pairs=springs["pairs"], spring_rest=springs["rest_length"],
             spring_ks=springs["stiffness"], spring_kd=springs["damping"],
             meta=json.dumps(jsonable(meta)))
    print(f"# wrote {path}: {n} x {n}, {len(springs['pairs'])} springs, "
          f"{len(scene.triangles)} triangles, {len(scene.colliders)} colliders")


def grid_colours(n, pairs):
    """SolverVBD's colour groups for an n x n grid whose particle (i, j) is j n + i:
    (i mod 3, j mod 3) (``newton_peer.grid_colouring``); raises if a spring joins two
    particles of one colour."""
    groups, colours = grid_colouring(n)
    if np.any(colours[pairs[:, 0]] == colours[pairs[:, 1]]):
        raise SystemExit("a spring joins two particles of one colour: not a grid cloth?")
    return groups


def contact_materials(meta, particle_mass):
    """(self-contact ke, kd, mu; per collider (ke, kd, mu) for its shape) such that
    Newton's mix of the two (mean ke and kd, geometric mean mu) is tcloth's collider law."""
    sc = meta["self_collision"]
    ke = sc["stiffness"]
    kd = 2.0 * sc["damping"] * np.sqrt(ke * particle_mass / 2.0)
    mu = sc["friction"]
    shapes = []
    for c in meta["colliders"]:
        c_kd = 2.0 * c["damping"] * np.sqrt(c["stiffness"] * particle_mass)
        c_mu = c["friction"] ** 2 / mu if mu > 0.0 else 0.0
        shapes.append((2.0 * c["stiffness"] - ke, 2.0 * c_kd - kd, c_mu))
    return (ke, kd, mu), shapes


def add_colliders(builder, meta, shapes):
    """tcloth's box and plane colliders as static Newton shapes with the given materials."""
    import newton
    import warp as wp
    for c, (ke, kd, mu) in zip(meta["colliders"], shapes):
        cfg = newton.ModelBuilder.ShapeConfig(ke=ke, kd=kd, mu=mu, margin=0.0)
        if c["kind"] == "box":
            rotation = wp.quat_from_matrix(wp.mat33(*np.ravel(c["rotation"])))
            builder.add_shape_box(-1, xform=wp.transform(wp.vec3(*c["center"]), rotation),
                                  hx=c["half_extents"][0], hy=c["half_extents"][1],
                                  hz=c["half_extents"][2], cfg=cfg)
        elif c["kind"] == "plane":
            normal = np.asarray(c["normal"], dtype=float)
            offset = float(normal @ np.asarray(c["center"], dtype=float))
            builder.add_shape_plane(plane=(*normal, -offset), width=0.0, length=0.0, cfg=cfg)
        else:
            raise SystemExit(f"collider kind {c['kind']!r} is not mapped to Newton")


def build(data, meta, device):
    """The Newton model of the exported scene (the module docstring) and the self-contact
    material (ke, kd, mu)."""
    import newton
    import warp as wp
    n = meta["n"]
    masses = data["masses"]
    radius = {c["thickness"] for c in meta["colliders"]}
    if len(radius) != 1:
        raise SystemExit("the colliders' thicknesses differ: Newton has one radius a particle")
    builder = newton.ModelBuilder(up_axis=newton.Axis.Y, gravity=tuple(meta["gravity"]))
    builder.add_cloth_mesh(pos=wp.vec3(0.0, 0.0, 0.0), rot=wp.quat_identity(), scale=1.0,
                           vel=wp.vec3(0.0, 0.0, 0.0),
                           vertices=data["rest_positions"].tolist(),
                           indices=data["triangles"].ravel().tolist(), density=0.0,
                           tri_ke=0.0, tri_ka=0.0, tri_kd=0.0, tri_drag=0.0, tri_lift=0.0,
                           edge_ke=0.0, edge_kd=0.0, particle_radius=radius.pop())
    pairs = data["spring_pairs"]
    for (i, j), ks, kd in zip(pairs, data["spring_ks"], data["spring_kd"]):
        builder.add_spring(int(i), int(j), float(ks), float(kd), control=0.0)
    builder.spring_rest_length = data["spring_rest"].astype(float).tolist()
    builder.particle_q = data["positions"].astype(float).tolist()
    builder.particle_qd = data["velocities"].astype(float).tolist()
    builder.particle_mass = masses.astype(float).tolist()
    builder.set_coloring(grid_colours(n, pairs))
    self_material, shapes = contact_materials(meta, float(masses.mean()))
    add_colliders(builder, meta, shapes)
    model = builder.finalize(device=device)
    model.soft_contact_ke, model.soft_contact_kd, model.soft_contact_mu = self_material
    return model


def make_solver(model, meta, args, contact):
    """SolverVBD on ``model`` owning a collision pipeline, self-contact on or off."""
    import newton
    sc = meta["self_collision"]
    pipeline = newton.CollisionPipeline(model, soft_contact_gap=args.gap)
    return newton.solvers.SolverVBD(
        model, iterations=args.iterations, friction_epsilon=sc["stick_velocity"],
        particle_enable_self_contact=contact,
        particle_self_contact_margin=sc["thickness"], particle_self_contact_gap=sc["skin"],
        collision_pipeline=pipeline)


def run(model, solver, steps, dt, rest=None):
    """Step ``solver`` ``steps`` times from the model's state: (final positions (N, 3)
    float64, each step's wall seconds, each step's largest spring strain (length - rest) /
    rest and particle speed, m/s). With ``rest`` (the springs' rest lengths) each step's
    state is checked, untimed: a step whose positions are not finite ends the run and is
    not counted; without it the last two are empty."""
    import warp as wp
    states = [model.state(), model.state()]
    pairs = model.spring_indices.numpy().reshape(-1, 2)
    times, strains, speeds = [], [], []
    for _ in range(steps):
        start = time.perf_counter()
        states[0].clear_forces()
        solver.step(states[0], states[1], None, None, dt)
        wp.synchronize_device(model.device)
        elapsed = time.perf_counter() - start
        if rest is not None:
            x, v = states[1].particle_q.numpy(), states[1].particle_qd.numpy()
            if not np.all(np.isfinite(x)):
                break
            length = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1)
            strains.append(float((length / rest).max() - 1.0))
            speeds.append(float(np.linalg.norm(v, axis=1).max()))
        times.append(elapsed)
        states.reverse()
    positions = states[0].particle_q.numpy().astype(np.float64)
    return positions, np.array(times), np.array(strains), np.array(speeds)


def one_mode(model, meta, data, args, contact):
    """One mode's numbers (module docstring), its step times and end positions; a
    throwaway solver's one step first."""
    count_crossings = numpy_reference("crossings").count_crossings
    run(model, make_solver(model, meta, args, contact), 1, args.dt)
    positions, times, strains, speeds = run(
        model, make_solver(model, meta, args, contact), args.steps, args.dt,
        data["spring_rest"])
    wall, steps = float(times.sum()), len(times)
    torn = np.nonzero(strains > STRAIN_BOUND)[0]
    result = {"wall_s": wall, "s_per_sim_s": wall / max(steps * args.dt, 1e-30),
              "steps": steps, "mean_height_m": float(positions[:, 1].mean()),
              "max_strain": float(strains.max(initial=0.0)),
              "max_speed_mps": float(speeds.max(initial=0.0))}
    if len(torn):
        result["torn_at_step"] = int(torn[0]) + 1
    else:
        result["crossings"] = int(count_crossings(positions, data["triangles"]))
    return result, times, positions


def simulate(args):
    """Build the exported scene in Newton, run each mode, print and save the numbers."""
    import newton
    import warp as wp
    wp.config.quiet = True
    wp.init()
    with np.load(args.scene) as npz:
        data = {key: npz[key] for key in npz.files}
    meta = json.loads(str(data["meta"]))
    model = build(data, meta, args.device)
    n = meta["n"]
    summary = {"newton": newton.__version__, "warp": wp.config.version, "solver": "vbd",
               "device": args.device, "iterations": args.iterations, "dt": args.dt,
               "gap": args.gap, "n": n}
    arrays = {}
    for mode in args.modes.split(","):
        result, times, positions = one_mode(model, meta, data, args, mode == "on")
        for key, value in result.items():
            print(f"newton_fold.{n}x{n}.vbd.{mode}_{key}: {value:.6g}", flush=True)
            summary[f"{mode}_{key}"] = value
        arrays[f"{mode}_step_times"], arrays[f"{mode}_positions"] = times, positions
    if summary.get("on_steps") and summary.get("off_steps"):
        summary["ratio"] = summary["on_s_per_sim_s"] / summary["off_s_per_sim_s"]
        print(f"newton_fold.{n}x{n}.vbd.ratio: {summary['ratio']:.6g}")
    if args.out:
        np.savez(args.out, triangles=data["triangles"], summary=json.dumps(summary), **arrays)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--export", help="tcloth's venv: write the n x n fold to this .npz")
    ap.add_argument("--n", type=int, default=64, help="--export's grid size")
    ap.add_argument("--state", default=os.path.join(HERE, "data", "fold_40x40.npz"),
                    help="--export's folded 40 x 40 state (as bench_self_collision.py)")
    ap.add_argument("--scene", help="newton's venv: run the fold exported to this .npz")
    ap.add_argument("--steps", type=int, default=60)
    ap.add_argument("--dt", type=float, default=1.0 / 60.0)
    ap.add_argument("--iterations", type=int, default=10)
    ap.add_argument("--gap", type=float, default=0.05,
                    help="particle-shape contact detection reach beyond the radius, m")
    ap.add_argument("--modes", default="on,off", help="self-contact on, off or both")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--out", default=None, help="--scene's result .npz")
    args = ap.parse_args()
    if (args.export is None) == (args.scene is None):
        ap.error("give one of --export and --scene")
    if args.export:
        export(args.export, args.n, args.state)
    else:
        simulate(args)


if __name__ == "__main__":
    main()
