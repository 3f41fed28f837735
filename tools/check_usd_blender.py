"""Does Blender open tcloth's USD? Simulate a scene script into a USD stage with
``tcloth.record_usd``, import it headless with Blender's own importer (``bpy``, Blender as a
Python module: ``bpy.ops.wm.usd_import``) and compare each cloth's vertices, at frames 0
and N, with the simulator's positions after Blender's axis conversion (USD y up ->
Blender z up: (x, y, z) -> (x, -z, y)). Then the other way: Blender exports the imported
scene at frame 0 (``bpy.ops.wm.usd_export``: z up, its own transforms) and
``tcloth.load_usd`` reads each cloth back. Prints greppable lines:

    usd_blender.<cloth>.vertices: <Blender's> (simulator: <n>)
    usd_blender.<cloth>.frame_<k>.max_error_m: <value>
    usd_blender.back_in.<cloth>.max_error_m: <value>     (Blender's export, read by tcloth)
    usd_blender.result: ok | failed: <why>

and exits 1 where it failed (a vertex off by more than 1e-5 m, a cloth missing, a count
that differs). ``--render PNG`` also renders frame N with Blender's Workbench engine, the
colours USD's ``displayColor`` (docs/img/usd_blender.png).

bpy needs Python 3.11 (bpy 5.0 on PyPI); where the project runs another Python, put it in a
venv of its own (``python3.11 -m venv /work/bpyvenv && /work/bpyvenv/bin/pip install bpy``)
and name it with ``--blender-python`` (default: $TCLOTH_BPY_PYTHON, /work/bpyvenv/bin/python,
or this Python where it imports bpy).

Usage: python tools/check_usd_blender.py [--script scenes/cloth_on_sphere.py]
           [--frames 30] [--set NAME=VALUE ...] [--out out/usd_check] [--render PNG]
"""
import argparse
import importlib.util
import math
import os
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
TOLERANCE = 1e-5        # m
DEFAULT_BPY = "/work/bpyvenv/bin/python"


def blender_python(given):
    """The Python that runs Blender's module, or None with none to be found."""
    for candidate in (given, os.environ.get("TCLOTH_BPY_PYTHON"), DEFAULT_BPY):
        if candidate and os.path.exists(candidate):
            return candidate
    return sys.executable if importlib.util.find_spec("bpy") else None


def simulate(args):
    """Write the USD stage and the simulator's cloth positions at frames 0 and N (npz);
    returns (usd path, npz path)."""
    import tcloth
    from tcloth.app.script import build_scene, load_script, parse_settings, timing, \
        with_options
    module, cfg = load_script(args.script)
    cfg = with_options(cfg, args.script, {"frames": ("--frames", args.frames)})
    tcloth.init(arch="cpu", precision=cfg["precision"])
    scene = build_scene(module, args.script, parse_settings(module, args.script, args.set))
    dt, steps = timing(cfg, scene)
    sim = tcloth.Simulator(scene, cfg["integrator"], dt=dt, **cfg["options"])
    os.makedirs(args.out, exist_ok=True)
    usd = os.path.join(args.out, "scene.usdc")
    ids = [np.ravel(c.particles) for c in scene.cloths]
    first = sim.positions()
    tcloth.record_usd(sim, usd, frames=cfg["frames"], steps_per_frame=steps, fps=cfg["fps"],
                      progress=False, cloth_colours=cfg["render"].get("cloth_colours"))
    last = sim.positions()
    camera = tcloth.Camera.from_config(cfg["camera"], scene.positions)
    expected = os.path.join(args.out, "expected.npz")
    arrays = {f"cloth_{k}.frame_0": first[i] for k, i in enumerate(ids)}
    arrays.update({f"cloth_{k}.frame_{cfg['frames'] - 1}": last[i] for k, i in enumerate(ids)})
    np.savez(expected, **arrays, camera_eye=camera.eye, camera_target=camera.target,
             camera_fov=camera.fov, size=(cfg["width"], cfg["height"]))
    return usd, expected


def blender_frame(bpy, obj, frame):
    """(V,3) world positions of a Blender object's evaluated mesh at a frame."""
    bpy.context.scene.frame_set(frame)
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = evaluated.to_mesh()
    co = np.empty(3 * len(mesh.vertices))
    mesh.vertices.foreach_get("co", co)
    matrix = np.array(evaluated.matrix_world)
    evaluated.to_mesh_clear()
    return co.reshape(-1, 3) @ matrix[:3, :3].T + matrix[:3, 3]


def compare(usd, expected):
    """Import the stage into an empty Blender scene and compare; returns failures."""
    import bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.usd_import(filepath=os.path.abspath(usd))
    data = np.load(expected)
    failures = []
    for key in sorted(k for k in data.files if k.startswith("cloth_")):
        name, frame = key.split(".")
        frame = int(frame[len("frame_"):])
        obj = bpy.data.objects.get(name)
        if obj is None:
            failures.append(f"no Blender object {name!r}")
            continue
        got = blender_frame(bpy, obj, frame)
        want = data[key].astype(np.float64)
        want = np.stack([want[:, 0], -want[:, 2], want[:, 1]], 1)   # y up -> z up
        if frame == 0:
            print(f"usd_blender.{name}.vertices: {len(got)} (simulator: {len(want)})")
        if got.shape != want.shape:
            failures.append(f"{name} has {len(got)} vertices in Blender, {len(want)} simulated")
            continue
        error = float(np.abs(got - want).max())
        print(f"usd_blender.{name}.frame_{frame}.max_error_m: {error:.3g}")
        if not error <= TOLERANCE:
            failures.append(f"{name} at frame {frame} is {error:.3g} m off (> {TOLERANCE})")
    if not any(k.startswith("cloth_") for k in data.files):
        failures.append("the scene has no cloth")
    bpy.context.scene.frame_set(0)
    bpy.ops.wm.usd_export(filepath=exported(usd), export_animation=False)
    return failures


def exported(usd):
    """Where Blender's export of the imported stage goes."""
    return os.path.join(os.path.dirname(os.path.abspath(usd)), "from_blender.usdc")


def back_in(usd, expected):
    """Each cloth of Blender's export read by tcloth against frame 0; returns failures."""
    import tcloth
    from pxr import Usd, UsdGeom
    data, path = np.load(expected), exported(usd)
    stage = Usd.Stage.Open(path)
    failures = []
    for key in sorted(k for k in data.files if k.endswith(".frame_0")):
        name = key.split(".")[0]
        prim = next((p.GetPath() for p in stage.Traverse()
                     if p.IsA(UsdGeom.Mesh) and p.GetName() == name), None)
        if prim is None:
            failures.append(f"Blender's export has no Mesh {name!r}")
            continue
        vertices, _ = tcloth.load_usd(path, str(prim))
        error = float(np.abs(vertices - data[key]).max())
        print(f"usd_blender.back_in.{name}.max_error_m: {error:.3g}")
        if not error <= TOLERANCE:
            failures.append(f"{name} read back from Blender's export is {error:.3g} m off")
    return failures


def render(png, expected, frame):
    """Frame ``frame`` of the imported stage through tcloth's camera, Workbench engine."""
    import bpy
    from mathutils import Vector
    data = np.load(expected)
    scene = bpy.context.scene
    turn = lambda v: Vector((v[0], -v[2], v[1]))     # noqa: E731  y up -> z up
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(camera)
    scene.camera = camera
    eye, target = turn(data["camera_eye"]), turn(data["camera_target"])
    camera.location = eye
    camera.rotation_euler = (target - eye).to_track_quat("-Z", "Y").to_euler()
    camera.data.sensor_fit = "VERTICAL"
    camera.data.angle_y = math.radians(float(data["camera_fov"]))
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.shading.color_type = "VERTEX"
    scene.display.shading.show_shadows = True
    scene.display.shading.show_cavity = True
    scene.view_settings.view_transform = "Standard"     # displayColor as it is
    scene.world = bpy.data.worlds.new("sky")
    scene.world.color = (0.55, 0.65, 0.8)
    scene.render.resolution_x, scene.render.resolution_y = (int(v) for v in data["size"])
    scene.render.resolution_percentage = 100
    scene.render.filepath = os.path.abspath(png)
    scene.frame_set(frame)
    bpy.ops.render.render(write_still=True)
    print(f"usd_blender.render: {png} (frame {frame})")


def check(args):
    """The Blender side: compare (and render); exit 1 on a failure."""
    failures = compare(args.check[0], args.check[1])
    if args.render:
        last = max(int(k.split("frame_")[1]) for k in np.load(args.check[1]).files
                   if ".frame_" in k)
        render(args.render, args.check[1], last)
    print("usd_blender.blender: " + ("ok" if not failures else "failed: " + "; ".join(failures)))
    sys.exit(1 if failures else 0)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--script", default=os.path.join(HERE, "..", "scenes", "cloth_on_sphere.py"))
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--set", action="append", metavar="NAME=VALUE",
                    help="a build() parameter of the script (repeatable)")
    ap.add_argument("--out", default=os.path.join("out", "usd_check"))
    ap.add_argument("--render", help="also render the last frame in Blender to this PNG")
    ap.add_argument("--blender-python", help="the Python with bpy (see the docstring)")
    ap.add_argument("--check", nargs=2, metavar=("USD", "NPZ"),
                    help="(run by the tool itself under bpy's Python) import and compare")
    args = ap.parse_args(argv)
    if args.check:
        return check(args)
    python = blender_python(args.blender_python)
    if python is None:
        print("usd_blender.result: skipped: no Python with bpy (pip install bpy, Python 3.11; "
              "--blender-python or $TCLOTH_BPY_PYTHON names it)")
        return 2
    usd, expected = simulate(args)
    command = [python, os.path.abspath(__file__), "--check", usd, expected]
    if args.render:
        command += ["--render", args.render]
    done = subprocess.run(command, capture_output=True, text=True)
    lines = [line for line in done.stdout.splitlines() if line.startswith("usd_blender.")]
    print("\n".join(line for line in lines if not line.startswith("usd_blender.blender:")))
    said = lines[-1] if lines else ""
    if not said.startswith("usd_blender.blender:"):
        failures = [f"Blender's Python exited {done.returncode}: "
                    f"{done.stderr.strip().splitlines()[-1:] or ''}"]
    else:
        failures = [] if said.endswith(": ok") else [said.split(": ", 1)[1]]
        failures += back_in(usd, expected)
    print("usd_blender.result: " + ("ok" if not failures else "failed: " + "; ".join(failures)))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
