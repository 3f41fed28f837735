"""The stored results the regression tests compare today's against, and how both sides
make them from the repository's scene scripts (``scripts``):

Scene snapshots (``tests/test_scene_regression.py``; tools/scene_snapshot.py writes them):
the positions of every scene script after SECONDS of simulated time, each scene built with
its default parameters and run with its CONFIG integrator and dt, in float64 on the CPU.
They are compared within TOLERANCE (m), not bit for bit: a CPU with other vector units
(AVX-512 against AVX2) or another libm rounds some operations differently, and a
contact-rich scene amplifies the difference. Float64 keeps that far below what a real
change does (docs/benchmarks.md, "Fast math and the scene snapshots"):
  - perturbing the initial positions by 1e-15 m (a few float64 ulps) moves the most
    chaotic scene (cloth_pile) by 5.5e-13 m after 0.1 s;
  - a spring constant changed by 1e-3 moves every scene whose springs are loaded within
    0.1 s by 2.6e-8 m (tablecloth) to 1.3e-5 m (cloth_pile).
SECONDS is short enough that the folding and piling scenes have not yet turned chaotic
(after 0.15 s a 1e-15 m perturbation grows to 2e-4 m in fold).

Golden pictures (``tests/test_render_golden.py``; tools/render_golden.py draws them):
every scene at two moments (TIMES), its particles' positions there and the picture the
renderer draws of them. Each scene is simulated with its CONFIG (integrator, dt, steps a
frame) to the first whole frame at or past each moment; the picture is drawn of the state
``posed`` rebuilds from the stored positions (the scene's colliders where they are at that
time), at WIDTH x HEIGHT with supersampling SUPERSAMPLE and the scene's camera and render
options.
"""
import numpy as np

import tcloth
from tcloth.app.script import timing
from tcloth.scene.scene import KIND_CODE

from .scripts import scene_names, script

SECONDS = 0.1
TOLERANCE = 1e-9
TIMES = (0.2, 1.5)            # s: the moments drawn
WIDTH, HEIGHT, SUPERSAMPLE = 160, 120, 2


def scale_structural(scene, factor):
    """Multiply the structural springs' constant k_s by ``factor`` (a real change, for the
    tolerance test); the scene's structural springs must share one k_s."""
    springs = scene.springs
    ks = np.unique(springs["stiffness"][springs["kind"] == KIND_CODE["structural"]])
    if len(ks) != 1:
        raise ValueError(f"the structural springs have {len(ks)} constants, not one")
    scene.set_spring_parameters("structural", stiffness=float(ks[0]) * factor)


def run_scene(name, seconds=SECONDS, integrator=None, dt=None, stiffness_scale=1.0):
    """(N,3) positions of scenes/NAME.py after ``seconds``; integrator and dt replace the
    scene's own where given. Needs tcloth.init(precision="f64") for the stored snapshot."""
    module, cfg = script(name)
    scene = module.build()
    if stiffness_scale != 1.0:
        scale_structural(scene, stiffness_scale)
    dt = dt or cfg["dt"]
    sim = tcloth.Simulator(scene, integrator=integrator or cfg["integrator"], dt=dt,
                           **({} if integrator else cfg["options"]))
    sim.step(int(round(seconds / dt)))
    return sim.positions()


def snapshot(seconds=SECONDS, integrator=None, dt=None, stiffness_scale=1.0, names=None):
    """dict scene name -> ``run_scene``'s positions (of every scene, or of ``names``)."""
    return {name: run_scene(name, seconds, integrator, dt, stiffness_scale)
            for name in names or scene_names()}


def posed(module, dt, steps, positions, sim=None):
    """A Simulator of the script's scene (``sim``, or a new one with time step dt) as
    ``steps`` steps of dt in (none taken) with its particles at ``positions``: its
    colliders (moving, turning, keyframed, deforming) where they are at that time."""
    sim = sim or tcloth.Simulator(module.build(), "symplectic_euler", dt=dt)
    sim.num_steps = int(steps)
    if steps:
        sim.model.colliders.advance(sim.time - dt, dt)
    sim.set_state(positions=positions)
    return sim


def draw(sim, cfg, **options):
    """The golden picture of a simulator's state: WIDTH x HEIGHT, the scene's camera."""
    return tcloth.render(sim, WIDTH, HEIGHT, camera=cfg["camera"], supersample=SUPERSAMPLE,
                         **{**cfg["render"], **options})


def frames(name):
    """{<name>.dt, .steps (F,), .positions (F, N, 3) float32, .images (F, H, W, 3)}."""
    module, cfg = script(name)
    tcloth.init(arch="cpu", precision=cfg["precision"])
    scene = module.build()
    dt, per_frame = timing(cfg, scene)
    sim = tcloth.Simulator(scene, cfg["integrator"], dt=dt, **cfg["options"])
    steps, positions = [], []
    for moment in TIMES:
        target = int(np.ceil(moment * cfg["fps"] - 1e-9)) * per_frame
        sim.step(target - sim.num_steps)
        steps.append(sim.num_steps)
        positions.append(sim.positions().astype(np.float32))
    images = [draw(posed(module, dt, k, x), cfg) for k, x in zip(steps, positions)]
    return {f"{name}.dt": np.float64(dt), f"{name}.steps": np.array(steps),
            f"{name}.positions": np.stack(positions), f"{name}.images": np.stack(images)}
