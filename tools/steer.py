"""Steer a towel by its held corners: the two corners of its near edge move so that it
lands folded in half on a table, found by gradient descent through the simulation
(``tcloth.grad``, L-BFGS from SciPy over the corners' velocities at every step).

The towel (--n x --n particles, 0.4 m, 0.1 kg, hinge bending) lies flat on a table (a plane
with friction 0.4); backward Euler at dt = 1/60 (frame rate) for --steps steps, the last
--rest of them with the corners at rest (the towel settles). The target is the towel
folded in half across its middle row (--n is odd): the near half turned over onto the far
half, the middle row the crease. (Folded between two rows, as an even --n would have it, the
target puts the two rows on one line though springs 1/(n-1) of the towel long join them:
a target no motion reaches: at n = 8 the descent stopped at 0.012 m^2.) The loss is
the squared distance to the target at the last step. The descent starts from the motion a
person would try first: each corner over a half circle about the middle line. Each corner's path is --knots
stretches of constant velocity (piecewise linear), at most 0.8 m/s along each axis. With
--layer T the towel has self-collision of thickness T (differentiated through each step's
contacts and the guard's projection, docs/grad.md) and the target's near half lies T
above the far half; without it (the default: backward Euler's Newton with self-collision
solves by CG, not multigrid, and a gradient costs about ten times as much) the
turned-over half lies at the table's height through the far half, as the target says.

Prints ``steer.loss.still`` (the corners held still), ``steer.loss.start`` (the half
circles), ``steer.loss.end``, ``steer.loss.reduction`` (still / end, the issue's target: at
least 100) and ``reduction_from_start``, iterations and seconds, and renders the optimised run
(<out>/steer.png: four frames side by side; --video adds <out>/steer.mp4).

Usage: python tools/steer.py [--n 13] [--steps 90] [--rest 20] [--iterations 60]
                             [--knots 6] [--layer 0] [--out docs/img] [--video]
                             [--quick]
"""
import argparse
import os
import time

import numpy as np

import tcloth
from tcloth import grad

SIZE, MASS, THICKNESS = 0.4, 0.1, 0.005
SPEED = 0.8             # the corners' largest speed along each axis, m/s


def towel(n, layer):
    """The towel flat on the table (a plane at y = 0), its near edge's corners held; with
    self-collision of thickness ``layer`` (none where it is 0)."""
    scene = tcloth.Scene(air_drag=0.02)
    scene.add_cloth(resolution=(n, n), size=(SIZE, SIZE), mass=MASS,
                            center=(0.0, THICKNESS, 0.0), structural=(400.0, 0.4),
                            shear=(100.0, 0.1), flexion=None, pinned=[(0, 0), (n - 1, 0)])
    scene.set_bending(2e-5)
    scene.add_plane((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), friction=0.4, thickness=THICKNESS)
    if layer > 0.0:
        scene.set_self_collision(thickness=layer, friction=0.4)
    return scene


def folded(scene, layer):
    """The towel folded across its middle row: the rows before it (the near half, z below
    the middle) mirrored onto the far half, ``layer`` above it."""
    x = scene.positions.copy()
    z = x[:, 2]
    middle = 0.5 * (z.min() + z.max())
    near = z < middle
    x[near, 2] = 2.0 * middle - z[near]
    x[near, 1] += layer
    return x


class Objective:
    """Loss and gradient over the corners' motion, for SciPy: ``knots`` stretches of
    constant velocity per corner over the steps before the rest (piecewise-linear
    paths). A run the simulator stops (InstabilityError: a torn towel) counts as a loss
    ten times the start's, which the line search backs away from."""

    def __init__(self, trajectory, loss, moving, knots):
        self.trajectory, self.loss = trajectory, loss
        self.shape = (trajectory.steps, len(trajectory.pinned), 3)
        self.knot = np.minimum(np.arange(moving) * knots // moving, knots - 1)
        self.knots, self.calls, self.worst = knots, 0, None

    def size(self):
        return self.knots * self.shape[1] * 3

    def arc(self, radius):
        """The first guess: each corner over a half circle of ``radius`` about the middle
        line (up, over and down onto the far edge), at even speed per stretch."""
        ends = np.arange(self.knots + 1) / self.knots
        path = np.stack([np.zeros_like(ends), radius * np.sin(np.pi * ends),
                         -radius * np.cos(np.pi * ends)], axis=1)
        seconds = np.bincount(self.knot, minlength=self.knots) * self.trajectory.sim.dt
        velocity = np.diff(path, axis=0) / seconds[:, None]
        return np.repeat(velocity[:, None, :], self.shape[1], axis=1).ravel()

    def controls(self, z):
        u = np.zeros(self.shape)
        u[:len(self.knot)] = z.reshape(self.knots, *self.shape[1:])[self.knot]
        return u

    def __call__(self, z):
        self.calls += 1
        self.trajectory.set("controls", self.controls(z))
        try:
            result = self.trajectory.gradient(self.loss, wrt=["controls"])
        except tcloth.InstabilityError as error:
            print(f"# gradient {self.calls}: the towel tore ({str(error)[:60]}...)", flush=True)
            return 10.0 * self.worst, np.zeros_like(z)
        self.worst = max(self.worst or 0.0, result.loss)
        print(f"# gradient {self.calls}: loss {result.loss:.6g} "
              f"({result.forward_seconds + result.backward_seconds:.2f} s)", flush=True)
        g = np.zeros((self.knots,) + self.shape[1:])
        np.add.at(g, self.knot, result.grad["controls"][:len(self.knot)])
        return result.loss, g.ravel()


def render_run(trajectory, controls, out, video):
    """The optimised run rendered: four frames side by side (and a video)."""
    from tcloth.render.video import write_png
    sim = trajectory.sim
    camera = tcloth.Camera(eye=(0.0, 0.55, -0.75), target=(0.0, 0.0, 0.02), fov=40.0)
    sim.reset()
    sim.set_state(trajectory.value("positions"), trajectory.value("velocities"))
    picks = np.linspace(0, trajectory.steps, 4).astype(int)
    frames, images = [], []
    for step in range(trajectory.steps + 1):
        if step in picks:
            images.append(tcloth.render(sim, width=320, height=240, camera=camera))
        if video:
            frames.append(tcloth.render(sim, width=480, height=360, camera=camera))
        if step < trajectory.steps:
            v = sim.velocities()
            v[trajectory.pinned] = controls[step]
            sim.set_state(velocities=v)
            sim.step(1)
    os.makedirs(out, exist_ok=True)
    write_png(os.path.join(out, "steer.png"), np.concatenate(images, axis=1))
    print(f"# wrote {os.path.join(out, 'steer.png')}")
    if video:
        import imageio_ffmpeg
        path = os.path.join(out, "steer.mp4")
        writer = imageio_ffmpeg.write_frames(path, (480, 360), fps=30, quality=7)
        writer.send(None)
        for frame in frames:
            writer.send(np.ascontiguousarray(frame))
        writer.close()
        print(f"# wrote {path}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=13)
    parser.add_argument("--steps", type=int, default=90)
    parser.add_argument("--rest", type=int, default=20)
    parser.add_argument("--iterations", type=int, default=60)
    parser.add_argument("--knots", type=int, default=6)
    parser.add_argument("--layer", type=float, default=0.0,
                        help="the self-collision thickness, m (default 0: none)")
    parser.add_argument("--out", default="docs/img")
    parser.add_argument("--video", action="store_true")
    parser.add_argument("--quick", action="store_true",
                        help="a test-sized run: 9 x 9, 60 steps, 30 iterations, no render")
    args = parser.parse_args()
    if args.quick:
        args.n, args.steps, args.rest, args.iterations = 9, 60, 15, 30
    if args.n < 3 or args.n % 2 == 0:
        parser.error(f"--n must be odd and at least 3, the fold along the middle row (got {args.n})")
    if args.layer < 0.0:
        parser.error(f"--layer must be >= 0 (got {args.layer})")
    from scipy.optimize import minimize
    tcloth.init(arch="cpu", precision="f64")
    scene = towel(args.n, args.layer)
    trajectory = grad.Trajectory(scene, steps=args.steps, dt=1.0 / 60.0,
                                 integrator="backward_euler", newton_tol=1e-5, cg_tol=1e-4,
                                 adjoint_tol=1e-6)
    loss = grad.TargetPositions(folded(scene, args.layer), steps=args.steps)
    objective = Objective(trajectory, loss, args.steps - args.rest, args.knots)
    z0 = objective.arc(0.5 * SIZE)
    start = time.perf_counter()
    still = objective(np.zeros_like(z0))[0]
    first = objective(z0)[0]
    history = []
    result = minimize(objective, z0, jac=True, method="L-BFGS-B",
                      bounds=[(-SPEED, SPEED)] * len(z0), options={"maxiter": args.iterations},
                      callback=lambda z: history.append(z.copy()))
    seconds = time.perf_counter() - start
    controls = objective.controls(result.x)
    trajectory.set("controls", controls)
    final = trajectory.forward(loss)[0]
    print(f"steer.loss.still: {still:.6g}")
    print(f"steer.loss.start: {first:.6g}")
    print(f"steer.loss.end: {final:.6g}")
    print(f"steer.loss.reduction: {still / final:.6g}")
    print(f"steer.loss.reduction_from_start: {first / final:.6g}")
    print(f"steer.iterations: {len(history)}")
    print(f"steer.gradients: {objective.calls}")
    print(f"steer.seconds: {seconds:.4g}")
    print(f"steer.guarded_steps: {len(trajectory.guarded_steps)}")
    print(f"steer.projected_steps: {len(trajectory.projected_steps)}")
    if not args.quick:
        render_run(trajectory, controls, args.out, args.video)


if __name__ == "__main__":
    main()
