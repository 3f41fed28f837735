"""Frame-rate solvers at one step per frame on cloth landing on a small collider: does the
cloth hold, or tear? (issue "honest at one step per frame"; docs/realtime.md).

Cases (``CASES``):
  - ``sphere``: a 40 x 40, 0.6 m cloth of 0.117 kg (structural (1000, 0.05), shear
    (50, 0.02), flexion (5, 0.005), nothing pinned) dropped from 0.45 m onto a sphere of
    radius 0.06 m at y = 0.3, 29 steps of 1/60 s (the issue's case);
  - ``capsule``: a 32 x 32, 0.6 m denim cloth (``tcloth.Fabric`` preset) with
    self-collision dropped onto a capsule, 60 steps of 1/60 s.
Each runs with backward Euler, projective, and VBD and XPBD at their default one substep
and at ``substeps="auto"``, twice: with the instability test as users get it (does a
step raise, and which), and with it off, to see how far the solver would have stretched
the cloth. Checked with NumPy alone: each spring's strain from the positions.

Prints ``tearing.<case>.<solver>.<metric>: value`` lines (max_strain, raised_at_step,
spring_energy_end_J, substeps, ms_per_step (median), collider_paths_cut).

Usage: python tools/tearing.py [--cases sphere,capsule] [--solvers projective,xpbd_auto]
                               [--resolution N]
"""
import argparse
import time

import numpy as np

import tcloth
from tcloth.integrators.base import substep_count
from tcloth.scene.stability import gershgorin_dt

SOLVERS = {
    "backward_euler": ("backward_euler", {"newton_iterations": 50}),
    "projective": ("projective", {}),
    "vbd": ("vbd", {}),
    "vbd_auto": ("vbd", {"substeps": "auto"}),
    "xpbd": ("xpbd", {}),
    "xpbd_auto": ("xpbd", {"substeps": "auto"}),
}


def sphere(res):
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    scene.add_cloth(resolution=(res, res), size=(0.6, 0.6), center=(0.0, 0.45, 0.0),
                    plane="xz", mass=0.117, structural=(1000.0, 0.05), shear=(50.0, 0.02),
                    flexion=(5.0, 0.005), pinned=[])
    scene.add_sphere((0.0, 0.3, 0.0), 0.06)
    return scene, 29


def capsule(res):
    scene = tcloth.Scene(gravity=(0.0, -9.81, 0.0))
    scene.add_cloth(resolution=(res, res), size=(0.6, 0.6), center=(0.0, 0.45, 0.0),
                    plane="xz", fabric="denim", pinned=[])
    scene.add_capsule((0.0, 0.3, 0.0), 0.04, 0.15, rotation=np.array(
        [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    scene.set_self_collision(thickness=0.004)
    return scene, 60


CASES = {"sphere": (sphere, 40), "capsule": (capsule, 32)}


def strains(scene, x):
    """Each spring's (|x_ij| - l0) / l0 at positions x (NumPy)."""
    springs = scene.springs
    d = x[springs["pairs"][:, 0]] - x[springs["pairs"][:, 1]]
    return np.linalg.norm(d, axis=1) / springs["rest_length"] - 1.0


def spring_energy(scene, x):
    springs = scene.springs
    d = np.linalg.norm(x[springs["pairs"][:, 0]] - x[springs["pairs"][:, 1]], axis=1)
    return float(np.sum(0.5 * springs["stiffness"] * (d - springs["rest_length"]) ** 2))


def run(case, solver, res, checked):
    """The case with one solver: (max strain, step that raised or None, spring energy at
    the end, substeps, median ms a step, collider paths cut)."""
    build, _ = CASES[case]
    scene, steps = build(res)
    name, options = SOLVERS[solver]
    bounds = {} if checked else {"energy_bound": False, "strain_bound": None}
    sim = tcloth.Simulator(scene, name, dt=1 / 60, **bounds, **options)
    worst, raised, times = 0.0, None, []
    for _ in range(steps):
        start = time.perf_counter()
        try:
            sim.step()
        except tcloth.InstabilityError as err:
            raised = err.step
            break
        times.append(time.perf_counter() - start)
        worst = max(worst, float(strains(scene, sim.positions()).max()))
    substeps = options.get("substeps", 1)
    if substeps == "auto":
        substeps = substep_count("auto", 1 / 60, sim.integrator.options["iterations"],
                                 gershgorin_dt(scene))
    return (worst, raised, spring_energy(scene, sim.positions()), substeps,
            1e3 * float(np.median(times[1:] or times)),
            sim.contact_stats().get("collider_paths_cut", 0))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default=",".join(CASES))
    parser.add_argument("--solvers", default=",".join(SOLVERS))
    parser.add_argument("--resolution", type=int, help="cloth resolution (default per case)")
    args = parser.parse_args()
    tcloth.init(arch="cpu", precision="f32")
    for case in args.cases.split(","):
        res = args.resolution or CASES[case][1]
        for solver in args.solvers.split(","):
            _, raised, _, _, _, _ = run(case, solver, res, True)
            worst, _, energy, substeps, ms, cut = run(case, solver, res, False)
            key = f"tearing.{case}.{solver}"
            print(f"{key}.raised_at_step: {raised if raised is not None else 'none'}")
            print(f"{key}.max_strain: {worst:.4f}")
            print(f"{key}.spring_energy_end_J: {energy:.4g}")
            print(f"{key}.substeps: {substeps}")
            print(f"{key}.ms_per_step: {ms:.2f}")
            print(f"{key}.collider_paths_cut: {cut}", flush=True)


if __name__ == "__main__":
    main()
