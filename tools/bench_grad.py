"""The cost of a gradient through the simulation (tcloth.grad) against the forward run:
an n x n cloth held at two corners, --steps steps, a loss on its final positions, the
gradient with respect to every parameter. The cloth starts on a sphere (mu 0.3) it drapes
over; symplectic Euler at dt 2e-4, backward Euler at dt --implicit-dt (1/60; newton_tol
and adjoint_tol --tol, cg_tol 1e-6: the gradient of converged steps), projective dynamics
at the same dt (--iterations local/global iterations a step, Anderson acceleration of
depth --anderson, adjoint_tol --tol; the largest residual they leave, relative to the
first, and the steps left above forward_tol 1e-6 are reported: the gradient is the
converged step's). Side by side in one run, medians of --repeats:

  - forward: the simulator's steps alone (``Simulator.step(steps)``);
  - trajectory: the same steps as the gradient's forward run takes them (one at a time,
    each state copied out, every k-th kept);
  - gradient: the forward run and the backward run (each segment run again, then the
    steps' adjoints).

--self-collision T gives the cloth self-collision of thickness T (projective dynamics
does not take it); the steps the guard's projection changed and those the gradient
does not take are reported (``projected_steps``, ``guarded_steps``).

--check adds whether the gradient is right: the loss's central difference in gravity's
vertical component (a step of 1e-3 of its value) against the gradient's component
(``gravity_y_adjoint``, ``gravity_y_difference``, their ``gravity_y_error`` relative to
the difference).

Prints greppable lines ``grad.<integrator>.<n>x<n>.<metric>: value`` (seconds, the ratios
gradient / forward and gradient / trajectory, the checkpoints' memory against storing every
state) and writes <out>/grad_bench.csv.

Usage: python tools/bench_grad.py [--sizes 32] [--steps 120] [--repeats 3] [--tol 1e-8]
                                  [--iterations 100] [--anderson 0]
                                  [--implicit-dt 0.016667] [--check]
                                  [--integrators all]
                                  [--self-collision 0] [--precision f64] [--out docs]
                                  [--arch cpu]
"""
import argparse
import os
import time

import numpy as np

import tcloth
from benchcsv import write_csv
from tcloth import grad


def cloth(n, collider=True, layer=0.0):
    scene = tcloth.Scene(air_drag=0.01)
    scene.add_cloth(resolution=(n, n), size=(0.5, 0.5), center=(0.0, 0.3, 0.0), mass=0.5,
                    structural=(500.0, 0.5), shear=(200.0, 0.2), flexion=(100.0, 0.1),
                    pinned=[(0, 0), (n - 1, 0)])
    if collider:
        scene.add_sphere((0.0, 0.18, 0.1), 0.12, friction=0.3)     # touching the cloth
    if layer > 0.0:
        scene.set_self_collision(thickness=layer)
    return scene


def check(trajectory, loss, result):
    """The gradient's vertical gravity component against the loss's central difference."""
    step = 1e-3 * abs(trajectory.value("gravity")[1])
    difference = trajectory.central_difference(loss, "gravity", np.array([0.0, 1.0, 0.0]),
                                               step)
    adjoint = float(result.grad["gravity"][1])
    return {"gravity_y_adjoint": adjoint, "gravity_y_difference": difference,
            "gravity_y_error": abs(adjoint - difference) / abs(difference)}


def measure(integrator, n, steps, repeats, tol, iterations, anderson, layer, implicit_dt,
            checked):
    dt = 2e-4 if integrator == "symplectic_euler" else implicit_dt
    options = {"backward_euler": {"newton_tol": tol, "cg_tol": 1e-6, "adjoint_tol": tol},
               "projective": {"iterations": iterations, "anderson": anderson,
                              "adjoint_tol": tol}}.get(integrator, {})
    scene = cloth(n, True, layer)
    trajectory = grad.Trajectory(scene, steps=steps, dt=dt, integrator=integrator, **options)
    target = scene.positions + np.array([0.0, -0.05, 0.0])
    loss = grad.TargetPositions(target, steps=steps)
    trajectory.gradient(loss)                               # compiles everything once
    sim = trajectory.sim
    times = {"forward": [], "trajectory": [], "gradient": []}
    result = None
    for _ in range(repeats):
        sim.reset()
        start = time.perf_counter()
        sim.step(steps)
        times["forward"].append(time.perf_counter() - start)
        start = time.perf_counter()
        trajectory.forward(loss)
        times["trajectory"].append(time.perf_counter() - start)
        start = time.perf_counter()
        result = trajectory.gradient(loss)
        times["gradient"].append(time.perf_counter() - start)
    every = trajectory.checkpoint_every
    trajectory.checkpoint_every = 1
    stored = trajectory.gradient(loss).memory_bytes
    trajectory.checkpoint_every = every
    med = {key: float(np.median(value)) for key, value in times.items()}
    errors = check(trajectory, loss, result) if checked else {}
    return {**{"integrator": integrator, "n": n, "steps": steps, "dt": dt,
            "forward_s": med["forward"], "trajectory_s": med["trajectory"],
            "gradient_s": med["gradient"],
            "ratio_forward": med["gradient"] / med["forward"],
            "ratio_trajectory": med["gradient"] / med["trajectory"],
            "checkpoint_every": every, "memory_bytes": result.memory_bytes,
            "memory_every_state_bytes": stored,
            "adjoint_iterations": result.adjoint_iterations,
            "adjoint_residual": result.adjoint_residual,
            "forward_residual": result.forward_residual,
            "projected_steps": len(result.projected_steps),
            "guarded_steps": len(result.guarded_steps),
            "unconverged_steps": len(result.unconverged_steps)}, **errors}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="32")
    parser.add_argument("--steps", type=int, default=120)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--tol", type=float, default=1e-8)
    parser.add_argument("--iterations", type=int, default=100,
                        help="projective dynamics' iterations a step")
    parser.add_argument("--anderson", type=int, default=0,
                        help="projective dynamics' Anderson acceleration (0: off)")
    parser.add_argument("--integrators", default=",".join(grad.INTEGRATORS))
    parser.add_argument("--self-collision", type=float, default=0.0,
                        help="the cloth's self-collision thickness, m (0: none)")
    parser.add_argument("--implicit-dt", type=float, default=1.0 / 60.0,
                        help="backward Euler's and projective dynamics' dt, s")
    parser.add_argument("--check", action="store_true",
                        help="the gravity gradient against central differences")
    parser.add_argument("--precision", default="f64")
    parser.add_argument("--out", default="docs")
    parser.add_argument("--arch", default="cpu")
    args = parser.parse_args()
    tcloth.init(arch=args.arch, precision=args.precision)
    rows = []
    for n in (int(s) for s in args.sizes.split(",") if s):
        for integrator in args.integrators.split(","):
            row = measure(integrator, n, args.steps, args.repeats, args.tol, args.iterations,
                          args.anderson, args.self_collision, args.implicit_dt,
                          args.check)
            rows.append(row)
            for key, value in row.items():
                if key not in ("integrator", "n"):
                    print(f"grad.{integrator}.{n}x{n}.{key}: {value:.6g}")
    write_csv(os.path.join(args.out, "grad_bench.csv"), rows)


if __name__ == "__main__":
    main()
