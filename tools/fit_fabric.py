"""Recover a fabric's bending (warp and weft) and shear from measurements of its
simulation, by gradient descent through the simulation (``tcloth.grad``, L-BFGS from
SciPy on the parameters' logarithms).

The measurements, as a textile lab takes them: Peirce's cantilever (a strip along the warp
and one along the weft, each at two overhang lengths: the chord angle to the tip edge),
Cusick's drape (the drape coefficient of a 30 cm disc on an 18 cm support) and a bias
extension (a 5 x 15 cm strip cut at 45 degrees to the warp, clamped at its top edge, a
100 g bar at its bottom edge: how far the bar hangs below the strip's length). They are
simulated once with the true fabric (a preset), with 1 mm of Gaussian noise on every point
the clamps do not hold (the apparatus places those); the fit starts from another preset
and simulates the same specimens with its parameters.

The drape coefficient alone cannot give the shear (docs/grad.md): a 5 % change of G moves
it by 0.0007 where its noise is 0.003, and by 12 to 19 times less than the same change of
the bending does. The bias strip shears under its load (22 mm at denim's G, 16 mm less
per unit of log G), so it carries G to the fit; the drape coefficient checks the bending.

One scene holds the six specimens, run by backward Euler at dt = 0.05 s (heavily damped:
a static solve, as tools/cantilever.py) for --steps steps from one shape at rest: the
start fabric's, after --settle steps from flat (a disc started flat chooses its folds
early, and a change of 0.2 % in G can choose others: a jump of up to 0.06 in the drape
coefficient; from one draped shape it is smooth in the parameters). The loss compares
the measurements at the last step:

  - the strips (grid cloths of Peirce's width, 2.5 cm, 8 points across, clamped over two
    columns; stretch 2000 N/m and shear 5 N/m, nearly inextensible as the elastica, in
    the truth and the fit alike): the chord angle from the clamp line to the mean of the
    tip edge's 8 points, in degrees (1 mm of noise on each point moves the mean by
    0.35 mm);
  - the disc (a mesh cloth with the fabric's membrane and the geometric mean of its warp
    and weft bending, as tools/drape.py, clamped within the support's radius; the
    support's cylinder is left out, which the hanging fabric does not touch): its drape
    coefficient, with the shadow taken as
    the area inside its projected rim (the shoelace formula, differentiable; tools/drape.py
    rasterises the union of the triangles, the same where no fold hangs over the rim).

  - the bias strip (a mesh cloth with the fabric's membrane, its warp at 45 degrees to
    its length: its rest shape is the hanging strip turned by 45 degrees in its plane,
    and the membrane's warp is the world's x axis there): the drop of its bottom edge's
    mean below the clamp line less its length, in mm.

loss = sum over strips ((angle - measured) / 1 degree)^2 + ((DC - measured) / 0.01)^2
       + ((extension - measured) / 1 mm)^2.

Prints one line a parameter, ``fit.<parameter>.relative_error: <value>`` (bending_warp,
bending_weft, shear), the measurements, iterations and seconds.

Usage: python tools/fit_fabric.py [--truth denim] [--start fleece] [--cells 16]
                                  [--rings 10] [--steps 30] [--settle 60]
                                  [--iterations 40] [--seed 0] [--quick]
       python tools/fit_fabric.py --measured [--rings 24] (the measured fabrics' shear)
"""
import argparse
import importlib.util
import time
from pathlib import Path

import numpy as np

import tcloth
from tcloth import grad
from tcloth.scene.fabric import Fabric, preset
from tcloth.testing.specimens import RADIUS, SCALE_DC, SUPPORT, Specimens, add_disc

DT = 0.05
NOISE = 1e-3                                # m, on every unclamped point
# --measured: tools/drape.py's assumed shear to start from, and the bounds of the fit's G
START_SHEAR, SHEAR_BOUNDS = 10.0, (1.0, 1000.0)          # N/m
# L-BFGS-B stops where an iteration lowers the loss by less than this fraction of it: past
# the noise's minimum its line search otherwise evaluates the same point again and again
# (8 to 14 gradients of 80-90 s each at the default size, measured)
TOLERANCE = 1e-5
# backward Euler for the truth and the fit alike; Newton's cap: the first step from flat
# takes 29 (denim) to 51 (fleece) iterations at --quick's size, and an unconverged step's
# derivative is not the adjoint's
SOLVER = dict(integrator="backward_euler", dt=DT, newton_iterations=200, newton_tol=1e-7,
              cg_tol=1e-5)


class Fit:
    """Loss and gradient in p = log(B_warp, B_weft, G), for SciPy."""

    def __init__(self, trajectory, specimens, loss):
        self.trajectory, self.specimens, self.loss = trajectory, specimens, loss
        self.disc = 4             # the strips' rows of the rigidity, then the mesh cloths'
        self.calls = 0

    def apply(self, p):
        warp, weft, shear = np.exp(p)
        rigidity = self.specimens.rigidity.copy()
        rigidity[:self.disc] = (warp, weft)
        rigidity[self.disc:] = np.sqrt(warp * weft)
        self.trajectory.set("bending", rigidity)
        self.trajectory.set("membrane.shear", shear)

    def __call__(self, p):
        self.calls += 1
        self.apply(p)
        result = self.trajectory.gradient(self.loss, wrt=["bending", "membrane.shear"])
        warp, weft, shear = np.exp(p)
        gb = result.grad["bending"]
        mean = np.sqrt(warp * weft)
        d_mean = gb[self.disc:].sum()
        g_warp = gb[:self.disc, 0].sum() + d_mean * mean / (2.0 * warp)
        g_weft = gb[:self.disc, 1].sum() + d_mean * mean / (2.0 * weft)
        g = np.array([g_warp * warp, g_weft * weft, result.grad["membrane.shear"] * shear])
        print(f"# gradient {self.calls}: loss {result.loss:.6g} at B = ({warp:.4g}, "
              f"{weft:.4g}) N m, G = {shear:.4g} N/m "
              f"({result.forward_seconds + result.backward_seconds:.1f} s)", flush=True)
        return result.loss, g


def measured_fabrics():
    """tools/drape.py's MEASURED: name -> (density kg/m^2, B N m, measured drape
    coefficient)."""
    spec = importlib.util.spec_from_file_location("drape_tool", Path(__file__).parent / "drape.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.MEASURED


def fit_measured(args, minimize):
    """Each measured fabric's shear G fitted to its measured drape coefficient, its
    density and bending as measured and its stretch as tools/drape.py assumes (1000 N/m),
    from G = 10 N/m within SHEAR_BOUNDS. The disc first settles --settle steps from flat
    (disturbed as tools/drape.py does) at the starting G; every run starts from there."""
    for name, (density, bending, target) in measured_fabrics().items():
        key = name.replace(" ", "_")
        scene = tcloth.Scene(air_drag=1e-4)
        rim = add_disc(scene, Fabric(density, 1000.0, START_SHEAR, bending, name=name),
                       args.rings)
        trajectory = grad.Trajectory(scene, steps=args.steps, adjoint_tol=1e-8, **SOLVER)
        x, free = scene.positions, ~scene.pinned
        x[free, 1] -= 1e-3 * np.random.default_rng(args.seed).random(int(free.sum()))
        trajectory.sim.set_state(positions=x)
        trajectory.sim.step(args.settle)
        trajectory.set("positions", trajectory.sim.positions())
        loss = grad.DrapeCoefficient(rim, RADIUS, SUPPORT, args.steps, target, SCALE_DC)
        started = loss.measure(trajectory.sim.positions())[0]

        def objective(p):
            trajectory.set("membrane.shear", float(np.exp(p[0])))
            result = trajectory.gradient(loss, wrt=["membrane.shear"])
            print(f"# {name}: loss {result.loss:.6g} at G = {np.exp(p[0]):.4g} N/m "
                  f"({result.forward_seconds + result.backward_seconds:.1f} s)", flush=True)
            return result.loss, np.array([result.grad["membrane.shear"] * np.exp(p[0])])

        began = time.perf_counter()
        result = minimize(objective, [np.log(START_SHEAR)], jac=True, method="L-BFGS-B",
                          bounds=[tuple(np.log(SHEAR_BOUNDS))],
                          options={"maxiter": args.iterations})
        shear = float(np.exp(result.x[0]))
        trajectory.set("membrane.shear", shear)
        trajectory.forward(loss)
        fitted = loss.measure(trajectory.sim.positions())[0]
        print(f"fit.{key}.shear: {shear:.4g}")
        print(f"fit.{key}.drape_coefficient: {fitted:.4f}")
        print(f"fit.{key}.drape_coefficient_at_start: {started:.4f}")
        print(f"fit.{key}.measured: {target:.4f}")
        print(f"fit.{key}.gap: {fitted - target:+.4f}")
        print(f"fit.{key}.seconds: {time.perf_counter() - began:.4g}", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--truth", default="denim")
    parser.add_argument("--start", default="fleece")
    parser.add_argument("--cells", type=int, default=16)
    parser.add_argument("--rings", type=int, default=10)
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--settle", type=int, default=60)
    parser.add_argument("--iterations", type=int, default=40)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quick", action="store_true",
                        help="a test-sized run: 8 cells, 5 rings, 20 steps")
    parser.add_argument("--measured", action="store_true",
                        help="fit the shear of tools/drape.py's measured fabrics to their "
                             "drape coefficients instead (their disc at --rings)")
    args = parser.parse_args()
    if args.quick:
        args.cells, args.rings, args.steps = 8, 5, 20
    from scipy.optimize import minimize
    tcloth.init(arch="cpu", precision="f64")
    if args.measured:
        fit_measured(args, minimize)
        return
    truth, start = preset(args.truth), preset(args.start)
    # the fit's specimens: the start preset's shear and bending to begin with; their
    # shape at rest after --settle steps from flat is where every run starts
    fit_specimens = Specimens(Fabric(density=truth.density, stretch=truth.stretch,
                                     shear=start.shear, bending=start.bending),
                              args.cells, args.rings)
    trajectory = grad.Trajectory(fit_specimens.scene, steps=args.steps, adjoint_tol=1e-8,
                                 **SOLVER)
    trajectory.sim.set_state(positions=fit_specimens.hanging)
    trajectory.sim.step(args.settle)
    initial = trajectory.sim.positions().astype(np.float64)
    trajectory.set("positions", initial)
    # the measurements: the true fabric from the same shape
    specimens = Specimens(truth, args.cells, args.rings)
    sim = tcloth.Simulator(specimens.scene, **SOLVER)
    sim.set_state(positions=initial)
    sim.step(args.steps)
    rng = np.random.default_rng(args.seed)
    # the noise on every point the clamps do not hold (the apparatus places those)
    noise = NOISE * rng.standard_normal((sim.model.particle_count, 3))
    noise[specimens.scene.pinned] = 0.0
    shape = sim.positions() + noise
    measured = specimens.measure(shape)
    print(f"fit.measured.angles_deg: {', '.join(f'{a:.3f}' for a in measured[:4])}")
    print(f"fit.measured.drape_coefficient: {measured[4]:.4f}")
    print(f"fit.measured.bias_extension_mm: {measured[5]:.3f}")
    fit = Fit(trajectory, fit_specimens, grad.Sum(*fit_specimens.measures(args.steps, measured)))
    p0 = np.log([*start.bending, start.shear])
    began = time.perf_counter()
    result = minimize(fit, p0, jac=True, method="L-BFGS-B",
                      options={"maxiter": args.iterations, "ftol": TOLERANCE})
    seconds = time.perf_counter() - began
    warp, weft, shear = np.exp(result.x)
    for name, value, true in (("bending_warp", warp, truth.bending[0]),
                              ("bending_weft", weft, truth.bending[1]),
                              ("shear", shear, truth.shear)):
        print(f"fit.{name}.value: {value:.6g}")
        print(f"fit.{name}.truth: {true:.6g}")
        print(f"fit.{name}.relative_error: {abs(value - true) / true:.4g}")
    print(f"fit.loss: {result.fun:.6g}")
    # the same loss at the true parameters: below the fit's, the search stopped short;
    # above it, the noise moved the loss's minimum away from the truth
    fit.apply(np.log([*truth.bending, truth.shear]))
    print(f"fit.loss_at_truth: {trajectory.forward(fit.loss)[0]:.6g}")
    print(f"fit.iterations: {result.nit}")
    print(f"fit.gradients: {fit.calls}")
    print(f"fit.seconds: {seconds:.4g}")


if __name__ == "__main__":
    main()
