"""Recover a fabric's bending (warp and weft) and shear from measurements of its
simulation, by gradient descent through the simulation (``tcloth.grad``, L-BFGS from
SciPy on the parameters' logarithms).

The measurements, as a textile lab takes them: Peirce's cantilever (a strip along the warp
and one along the weft, each at two overhang lengths: the chord angle to the tip edge) and
Cusick's drape (the drape coefficient of a 30 cm disc on an 18 cm support). They are
simulated once with the true fabric (a preset), with 1 mm of Gaussian noise on every point
the clamps do not hold (the apparatus places those); the fit starts from another preset
and simulates the same specimens with its parameters.

One scene holds the five specimens, run by backward Euler at dt = 0.05 s (heavily damped:
a static solve, as tools/cantilever.py) for --steps steps, and the loss compares the
measurements at the last one:

  - the strips (grid cloths, clamped over two columns; stretch 2000 N/m and shear 5 N/m,
    nearly inextensible as the elastica, in the truth and the fit alike): their tip chord
    angle against the clamp, in degrees;
  - the disc (a mesh cloth with the fabric's membrane and the geometric mean of its warp
    and weft bending, as tools/drape.py, clamped within the support's radius; the
    support's cylinder is left out, which the hanging fabric does not touch): its drape
    coefficient, with the shadow taken as
    the area inside its projected rim (the shoelace formula, differentiable; tools/drape.py
    rasterises the union of the triangles, the same where no fold hangs over the rim).

loss = sum over strips ((angle - measured) / 1 degree)^2 + ((DC - measured) / 0.01)^2.

Prints one line a parameter, ``fit.<parameter>.relative_error: <value>`` (bending_warp,
bending_weft, shear), the measurements, iterations and seconds.

Usage: python tools/fit_fabric.py [--truth denim] [--start fleece] [--cells 16]
                                  [--rings 10] [--steps 60] [--iterations 40] [--quick]
"""
import argparse
import time

import numpy as np

import tcloth
from tcloth import grad
from tcloth.geometry.primitives import disc
from tcloth.scene.fabric import Fabric, preset

DT = 0.05
WIDTH, LENGTHS = 0.02, (0.03, 0.05)         # the strips: m (denim's chord angles 25-55 deg)
RADIUS, SUPPORT, HEIGHT = 0.15, 0.09, 0.3   # the drape: m
NOISE = 1e-3                                # m, on every unclamped point
SCALE_ANGLE, SCALE_DC = 1.0, 0.01           # the loss's units: 1 degree, 0.01
# backward Euler for the truth and the fit alike; Newton's cap: the first step from flat
# takes 29 (denim) to 51 (fleece) iterations at --quick's size, and an unconverged step's
# derivative is not the adjoint's
SOLVER = dict(integrator="backward_euler", dt=DT, newton_iterations=200, newton_tol=1e-7,
              cg_tol=1e-5)


class Specimens:
    """The five specimens of one fabric in one scene, and their measurements."""

    def __init__(self, fabric, cells, rings):
        self.scene = scene = tcloth.Scene(air_drag=1e-4)
        self.strips = []            # (cloth, family, clamp particle, tip edge particles)
        for s, (length, family) in enumerate([(l, f) for f in (0, 1) for l in LENGTHS]):
            self.strips.append(self._strip(scene, fabric, length, family, cells,
                                           origin=(0.3 + 0.25 * s, 1.0, 0.0)))
        vertices, triangles = disc(rings, RADIUS)
        vertices[:, 1] += HEIGHT
        clamped = np.flatnonzero(np.hypot(vertices[:, 0], vertices[:, 2]) <= SUPPORT + 1e-9)
        offset = scene.num_particles
        scene.add_mesh_cloth(vertices, [tuple(t) for t in triangles.tolist()], pinned=clamped,
                             fabric=fabric.mean_bending())
        radius = np.hypot(vertices[:, 0], vertices[:, 2])
        rim = np.flatnonzero(radius > RADIUS - 1e-9)
        self.rim = offset + rim[np.argsort(np.arctan2(vertices[rim, 2], vertices[rim, 0]))]
        self.rigidity = np.array(scene.bending["rigidity"], dtype=np.float64)

    @staticmethod
    def _strip(scene, fabric, length, family, cells, origin):
        """A strip along the warp (family 0: along x) or the weft (1: along z), clamped
        over its first two columns; the clamp line half a cell inside them."""
        dx = length / (cells - 1.5)
        size = (cells - 1) * dx
        strip = Fabric(density=fabric.density, stretch=2000.0, shear=5.0,
                       bending=fabric.bending)
        x0, y0, z0 = origin
        if family == 0:
            resolution, extent = (cells, 3), (size, WIDTH)
            center, clamp = (x0 + size / 2, y0, z0), [(i, j) for i in (0, 1) for j in range(3)]
        else:
            resolution, extent = (3, cells), (WIDTH, size)
            center, clamp = (x0, y0, z0 + size / 2), [(i, j) for i in range(3) for j in (0, 1)]
        cloth = scene.add_cloth(resolution=resolution, size=extent, center=center,
                                fabric=strip, pinned=clamp)
        p = cloth.particles
        line = p[1, :] if family == 0 else p[:, 1]          # the strip's middle line
        edge = p[:, -1] if family == 0 else p[-1, :]        # the tip's edge across the strip
        return len(scene.cloths) - 1, family, line[1], np.asarray(edge)

    def angles(self, x):
        """Each strip's chord angle below the horizontal, from the clamp line's middle to
        the middle of the tip's edge (the mean of its points), degrees, and its gradient."""
        values, grads = [], []
        for _, family, clamp, edge in self.strips:
            d = x[edge].mean(axis=0) - x[clamp]
            axis = 0 if family == 0 else 2
            along = d[axis]
            angle = np.degrees(np.arctan2(-d[1], abs(along)))
            r2 = along * along + d[1] * d[1]
            g = np.zeros_like(x)
            g_tip = np.zeros(3)
            g_tip[1] = -abs(along) / r2
            g_tip[axis] = d[1] / r2 * np.sign(along)
            g[edge] = g_tip / len(edge)
            g[clamp] = -g_tip
            values.append(angle)
            grads.append(np.degrees(g))
        return np.array(values), grads

    def drape(self, x):
        """The drape coefficient from the area inside the projected rim, and its
        gradient."""
        p = x[self.rim][:, [0, 2]]
        q = np.roll(p, -1, axis=0)
        area = 0.5 * float((p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]).sum())
        sign = 1.0 if area > 0 else -1.0
        ring = np.pi * (RADIUS ** 2 - SUPPORT ** 2)
        value = (abs(area) - np.pi * SUPPORT ** 2) / ring
        g = np.zeros_like(x)
        before = np.roll(p, 1, axis=0)
        g[self.rim, 0] = sign * 0.5 * (q[:, 1] - before[:, 1]) / ring
        g[self.rim, 2] = sign * 0.5 * (before[:, 0] - q[:, 0]) / ring
        return value, g

    def measure(self, x):
        return np.append(self.angles(x)[0], self.drape(x)[0])


def loss_for(specimens, measured, steps):
    """The fit's loss at the last step (see the module)."""

    def evaluate(step, x, v):
        angles, angle_grads = specimens.angles(x)
        dc, dc_grad = specimens.drape(x)
        ra = (angles - measured[:4]) / SCALE_ANGLE
        rd = (dc - measured[4]) / SCALE_DC
        value = float((ra * ra).sum() + rd * rd)
        g = 2.0 * rd / SCALE_DC * dc_grad
        for r, ga in zip(ra, angle_grads):
            g += 2.0 * r / SCALE_ANGLE * ga
        return value, g, None

    return grad.Loss(steps, evaluate)


class Fit:
    """Loss and gradient in p = log(B_warp, B_weft, G), for SciPy."""

    def __init__(self, trajectory, specimens, loss):
        self.trajectory, self.specimens, self.loss = trajectory, specimens, loss
        self.disc = len(specimens.rigidity) - 1
        self.calls = 0

    def apply(self, p):
        warp, weft, shear = np.exp(p)
        rigidity = self.specimens.rigidity.copy()
        rigidity[:self.disc] = (warp, weft)
        rigidity[self.disc] = np.sqrt(warp * weft)
        self.trajectory.set("bending", rigidity)
        self.trajectory.set("membrane.shear", shear)

    def __call__(self, p):
        self.calls += 1
        self.apply(p)
        result = self.trajectory.gradient(self.loss, wrt=["bending", "membrane.shear"])
        warp, weft, shear = np.exp(p)
        gb = result.grad["bending"]
        mean = np.sqrt(warp * weft)
        d_mean = gb[self.disc].sum()
        g_warp = gb[:self.disc, 0].sum() + d_mean * mean / (2.0 * warp)
        g_weft = gb[:self.disc, 1].sum() + d_mean * mean / (2.0 * weft)
        g = np.array([g_warp * warp, g_weft * weft, result.grad["membrane.shear"] * shear])
        print(f"# gradient {self.calls}: loss {result.loss:.6g} at B = ({warp:.4g}, "
              f"{weft:.4g}) N m, G = {shear:.4g} N/m "
              f"({result.forward_seconds + result.backward_seconds:.1f} s)", flush=True)
        return result.loss, g


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--truth", default="denim")
    parser.add_argument("--start", default="fleece")
    parser.add_argument("--cells", type=int, default=16)
    parser.add_argument("--rings", type=int, default=10)
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--iterations", type=int, default=40)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quick", action="store_true",
                        help="a test-sized run: 8 cells, 5 rings, 20 steps")
    args = parser.parse_args()
    if args.quick:
        args.cells, args.rings, args.steps = 8, 5, 20
    from scipy.optimize import minimize
    tcloth.init(arch="cpu", precision="f64")
    truth, start = preset(args.truth), preset(args.start)
    specimens = Specimens(truth, args.cells, args.rings)
    sim = tcloth.Simulator(specimens.scene, **SOLVER)
    sim.step(args.steps)
    rng = np.random.default_rng(args.seed)
    # the noise on every point the clamps do not hold (the apparatus places those)
    noise = NOISE * rng.standard_normal((sim.model.particle_count, 3))
    noise[specimens.scene.pinned] = 0.0
    shape = sim.positions() + noise
    measured = specimens.measure(shape)
    print(f"fit.measured.angles_deg: {', '.join(f'{a:.3f}' for a in measured[:4])}")
    print(f"fit.measured.drape_coefficient: {measured[4]:.4f}")
    # the fit: the same specimens, the start preset's shear and bending to begin with
    fit_specimens = Specimens(Fabric(density=truth.density, stretch=truth.stretch,
                                     shear=start.shear, bending=start.bending),
                              args.cells, args.rings)
    trajectory = grad.Trajectory(fit_specimens.scene, steps=args.steps, adjoint_tol=1e-8,
                                 **SOLVER)
    fit = Fit(trajectory, fit_specimens, loss_for(fit_specimens, measured, args.steps))
    p0 = np.log([*start.bending, start.shear])
    began = time.perf_counter()
    result = minimize(fit, p0, jac=True, method="L-BFGS-B",
                      options={"maxiter": args.iterations})
    seconds = time.perf_counter() - began
    warp, weft, shear = np.exp(result.x)
    for name, value, true in (("bending_warp", warp, truth.bending[0]),
                              ("bending_weft", weft, truth.bending[1]),
                              ("shear", shear, truth.shear)):
        print(f"fit.{name}.value: {value:.6g}")
        print(f"fit.{name}.truth: {true:.6g}")
        print(f"fit.{name}.relative_error: {abs(value - true) / true:.4g}")
    print(f"fit.loss: {result.fun:.6g}")
    print(f"fit.iterations: {result.nit}")
    print(f"fit.gradients: {fit.calls}")
    print(f"fit.seconds: {seconds:.4g}")


if __name__ == "__main__":
    main()
