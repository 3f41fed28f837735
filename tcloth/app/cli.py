"""The ``tcloth`` command line: ``tcloth render SCRIPT --out PATH``, ``tcloth view SCRIPT``,
``tcloth list``, ``tcloth sweep SPEC.toml --out DIR``. ``render --usd PATH`` writes the
animation as one OpenUSD stage beside the video (alone without ``--out``: docs/usd.md).

A scene script defines ``build(**params) -> tcloth.Scene`` and a dict ``CONFIG`` with any
of: description, integrator, dt, steps_per_frame, frames, fps, camera, width, height,
supersample, options (integrator options), render (Renderer options), precision
(``script.py``: loading, the defaults, the step a script without dt gets).
"""
import argparse
import glob
import os
import sys
import traceback
import warnings

from ..errors import DeviceWarning, InstabilityError, MissingExtraError, SceneError
from .script import (ScriptError, build_scene, describe, load_script, parse_settings, timing,
                     with_options)


def init(arch, precision):
    """tcloth.init for the command line: one line on what it runs on, and any
    DeviceWarning (a GPU asked for, a CPU or software driver given) as a line of its own."""
    from .. import runtime
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DeviceWarning)
        runtime.init(arch=arch, precision=precision)
    print(f"tcloth: running on {runtime.device()} in {precision}", file=sys.stderr)
    for w in caught:
        if issubclass(w.category, DeviceWarning):
            print(f"tcloth: warning: {w.message}", file=sys.stderr)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)


def _set_argument(parser):
    parser.add_argument("--set", action="append", metavar="NAME=VALUE",
                        help="a build() parameter of the script, e.g. --set resolution=[64,64]"
                             " --set thickness=0.004 (repeatable; VALUE a Python literal)")


def _device_arguments(parser):
    parser.add_argument("--arch", default="cpu", help="cpu | gpu | cuda | vulkan | metal | auto")
    parser.add_argument("--precision", choices=["f32", "f64"], help="float precision")


def _stepping_arguments(parser, steps, integrator_help):
    """--integrator, --dt, the steps a frame (their flag: ``steps``) and the device, as
    render and view take them."""
    parser.add_argument("--integrator", help=integrator_help)
    parser.add_argument("--dt", type=float, help="time step, s (steps per frame follow it: "
                                                 f"as many as fill a frame, unless {steps} "
                                                 "is given too)")
    parser.add_argument(steps, type=int, help="simulator steps per frame (default: the "
                                              "script's steps_per_frame; with --dt: as many "
                                              "as fill a frame)")
    _device_arguments(parser)


def _render_parser(parser):
    parser.add_argument("--out", help="output .mp4, or a folder for PNG frames "
                                      "(default out/NAME.mp4)")
    parser.add_argument("--frames", type=int, help="number of frames")
    _stepping_arguments(parser, "--steps-per-frame", "integrator name")
    parser.add_argument("--width", type=int, help="image width, pixels")
    parser.add_argument("--height", type=int, help="image height, pixels")
    parser.add_argument("--supersample", type=int, help="s x s samples per pixel")
    parser.add_argument("--meshes", help="also write each frame's cloth mesh (OBJ) here")
    parser.add_argument("--usd", help="also write the animation as one OpenUSD stage "
                                      "(.usda, .usdc, .usd, .usdz; without --out, only "
                                      "that: no video); needs the extra usd")
    _set_argument(parser)
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--verbose", action="store_true", help="tracebacks on errors")


def render_script(path, args):
    """Run one scene script as the command line asks. Returns the record() stats."""
    from ..sim.simulator import Simulator
    from ..render.usd import UsdWriter, check_usd_path
    from ..render.video import check_writable, record

    module, cfg = load_script(path)
    params = parse_settings(module, path, args.set)
    cfg = with_options(cfg, path, {key: ("--" + key.replace("_", "-"), getattr(args, key))
                                   for key in ("frames", "integrator", "dt", "steps_per_frame",
                                               "precision", "width", "height", "supersample")})
    name = os.path.splitext(os.path.basename(path))[0]
    out = args.out or (None if args.usd else os.path.join("out", name + ".mp4"))
    if out is not None:
        check_writable(out)
    if args.usd is not None:
        check_usd_path(args.usd)
    init(args.arch, cfg["precision"])
    scene = build_scene(module, path, params)
    dt, steps = timing(cfg, scene)
    frames, fps = cfg["frames"], cfg["fps"]
    print(f"tcloth: {frames} frames of {steps} step{'s' if steps > 1 else ''} of "
          f"dt = {dt:.6g} s: {(frames - 1) * steps * dt:.4g} s simulated, {frames / fps:.4g} s "
          f"of video at {fps:g} fps", file=sys.stderr)
    sim = Simulator(scene, cfg["integrator"], dt=dt, **cfg["options"])
    render = cfg["render"]
    writers = [] if args.usd is None else [
        UsdWriter(sim, args.usd, fps, render.get("cloth_colours"), render.get("particle_radius"))]
    stats = record(sim, out, frames=cfg["frames"], steps_per_frame=steps, fps=cfg["fps"],
                   width=cfg["width"], height=cfg["height"], camera=cfg["camera"],
                   supersample=cfg["supersample"], progress=not args.quiet,
                   mesh_dir=args.meshes, writers=writers, **render)
    print(f"tcloth: {split_summary(sim.step_stats(), sim.num_steps)}", file=sys.stderr)
    return stats


def split_summary(stats, steps):
    """One line on how a run's steps were split (``Simulator.step_stats``)."""
    if not stats["split_steps"]:
        return f"all {steps} steps whole (none split)"
    return (f"{stats['split_steps']} of {steps} steps split into {stats['pieces']} pieces "
            f"(at most {stats['finest']} a step; {stats['retries']} failed attempts "
            f"taken again finer)")


def view_script(path, args):
    """``tcloth view``: the scene in the live sandbox window."""
    from ..sim.simulator import Simulator
    from ..render.video import check_writable
    from ..viewer import DisplayError, Viewer, check_display

    module, cfg = load_script(path)
    params = parse_settings(module, path, args.set)
    cfg = with_options(cfg, path, {"integrator": ("--integrator", args.integrator),
                                   "dt": ("--dt", args.dt), "precision": ("--precision",
                                                                          args.precision),
                                   "steps_per_frame": ("--substeps", args.substeps),
                                   "frames": ("--frames", args.frames)})
    if args.screenshot is not None:
        check_writable(args.screenshot)
        if args.frames is None:
            raise ScriptError("--screenshot needs --frames N (the frame to save)")
    try:
        check_display()
    except DisplayError as e:
        raise ViewerUnavailable(str(e)) from None
    init(args.arch, cfg["precision"])
    scene = build_scene(module, path, params)
    if args.wind and scene.wind is None:
        scene.set_wind((0.0, 0.0, 0.0))
    dt, steps = timing(cfg, scene)
    print(f"tcloth: {steps} substep{'s' if steps > 1 else ''} of dt = {dt:.6g} s a frame: "
          f"{steps * dt:.4g} s simulated a frame", file=sys.stderr)
    sim = Simulator(scene, cfg["integrator"], dt=dt, grab=True, **cfg["options"])
    render = cfg["render"]
    try:
        viewer = Viewer(sim, substeps=steps,
                        camera=cfg["camera"], width=args.width, height=args.height,
                        ground=render.get("ground"), cloth_colours=render.get("cloth_colours"),
                        title=f"tcloth: {os.path.basename(path)}")
    except DisplayError as e:
        raise ViewerUnavailable(str(e)) from None
    shown = viewer.run(frames=args.frames, screenshot=args.screenshot)
    stats = viewer.controls.stats()
    print(f"{shown} frames of {viewer.controls.values['substeps']} substeps: "
          f"{stats['fps']:.1f} frames/s, {stats['ms_per_substep']:.3f} ms per substep "
          f"(medians of the last 30 frames)")
    if args.screenshot is not None:
        print(f"wrote {args.screenshot}")


class ViewerUnavailable(Exception):
    """No window can open here (exit code 2, one line)."""


def sweep_command(args):
    """``tcloth sweep``: run the spec, then one summary line per outcome."""
    from .sweep import run_sweep
    from .sweep.engine import FAILED
    try:
        rows = run_sweep(args.spec, args.out, workers=args.workers, scheduler=args.scheduler,
                         threads=args.threads, progress=not args.quiet)
    except KeyboardInterrupt:
        raise SweepFailed(f"interrupted; the finished cases are kept in {args.out!r}: run "
                          f"the same command again to resume") from None
    stable = sum(1 for r in rows if r["stable"])
    raised = sum(1 for r in rows if r["status"].startswith("error"))
    failed = sum(1 for r in rows if r["status"].startswith(FAILED))
    reused = sum(1 for r in rows if r["reused"])
    print(f"{len(rows)} cases ({len(rows) - reused} run now, {reused} from earlier runs): "
          f"{stable} stable, {len(rows) - stable - raised - failed} unstable, {raised} "
          f"raised, {failed} did not finish (see the status column); wrote "
          f"{os.path.join(args.out, 'results.csv')}")
    if failed:
        raise SweepFailed(f"{failed} of {len(rows)} cases did not finish; run the same "
                          f"command again to run them")


class SweepFailed(Exception):
    """Some cases of a sweep did not run to their end (exit code 4)."""


def _guarded(fn, verbose):
    try:
        fn()
    except SweepFailed as e:
        print(f"tcloth: {e}", file=sys.stderr)
        return 4
    except ViewerUnavailable as e:
        print(f"tcloth: cannot open the viewer: {e}", file=sys.stderr)
        return 2
    except (ScriptError, SceneError, MissingExtraError, InstabilityError) as e:
        if verbose:
            traceback.print_exc()
        kind = "unstable" if isinstance(e, InstabilityError) else "error"
        print(f"tcloth: {kind}: {e}", file=sys.stderr)
        return 3 if isinstance(e, InstabilityError) else 2
    except KeyboardInterrupt as e:      # Ctrl-C: what was kept (``record``), no traceback
        print(f"tcloth: {e or 'interrupted'}", file=sys.stderr)
        return 130
    return 0


def main(argv=None):
    parser = argparse.ArgumentParser(prog="tcloth", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p_render = sub.add_parser("render", help="render a scene script to a video or PNG frames")
    p_render.add_argument("script", help="path of a scene script, e.g. scenes/hanging_cloth.py")
    _render_parser(p_render)
    p_list = sub.add_parser("list", help="list scene scripts: the integrator, dt, steps a "
                                         "frame and particles each runs with, and a "
                                         "one-line description")
    p_list.add_argument("folder", nargs="?", default="scenes")
    p_sweep = sub.add_parser("sweep", help="run a parameter sweep (a TOML spec) on a process "
                                           "pool or a Dask cluster")
    p_sweep.add_argument("spec", help="the sweep spec, e.g. docs/sweeps/hanging_cloth.toml")
    p_sweep.add_argument("--out", required=True, help="output folder (rerun to resume)")
    p_sweep.add_argument("--workers", type=int, help="local worker processes "
                                                     "(default: one per core; 1: serial)")
    p_sweep.add_argument("--scheduler", help="a Dask scheduler address, tcp://HOST:PORT")
    p_sweep.add_argument("--threads", type=int, help="Taichi threads per worker "
                                                     "(default: cores / workers)")
    p_sweep.add_argument("--quiet", action="store_true", help="no progress bar")
    p_sweep.add_argument("--verbose", action="store_true", help="tracebacks on errors")
    p_view = sub.add_parser("view", help="the live sandbox: simulate a scene in a window and "
                                         "play with it")
    p_view.add_argument("script", help="path of a scene script, e.g. scenes/hanging_cloth.py")
    _stepping_arguments(p_view, "--substeps", "integrator name (switchable in the window)")
    p_view.add_argument("--width", type=int, default=1280, help="window width, pixels")
    p_view.add_argument("--height", type=int, default=800, help="window height, pixels")
    p_view.add_argument("--wind", action="store_true",
                        help="add a still wind to a scene without one, to turn up live")
    p_view.add_argument("--frames", type=int, help="stop after N frames")
    p_view.add_argument("--screenshot", help="save the window's image (PNG) at the last "
                                             "frame; needs --frames (no screen: xvfb-run -a)")
    p_view.add_argument("--verbose", action="store_true", help="tracebacks on errors")
    _set_argument(p_view)
    args = parser.parse_args(argv)
    if args.command == "view":
        return _guarded(lambda: view_script(args.script, args), args.verbose)
    if args.command == "sweep":
        return _guarded(lambda: sweep_command(args), args.verbose)
    if args.command == "list":
        scripts = sorted(glob.glob(os.path.join(args.folder, "*.py")))
        if not scripts:
            print(f"tcloth: error: no scene scripts in {args.folder!r}", file=sys.stderr)
            return 2
        rows = [(os.path.basename(s), *defaults(s), describe(s)) for s in scripts]
        header = ("script", "integrator", "dt", "steps a frame", "particles", "")
        widths = [max(len(str(r[i])) for r in rows + [header]) for i in range(5)]
        for row in [header] + rows:
            print(("  ".join(f"{str(c):<{w}}" for c, w in zip(row, widths)) + "  " + row[5])
                  .rstrip())
        return 0
    return _guarded(lambda: render_script(args.script, args), args.verbose)


def defaults(path):
    """(integrator, dt, steps a frame, particles) a scene script runs with as it ships:
    its CONFIG, and the rule of ``script.timing`` where it gives no dt. Question marks
    where the script does not load or build."""
    try:
        module, cfg = load_script(path)
        scene = build_scene(module, path)
        dt, steps = timing(cfg, scene)
    except (ScriptError, SceneError):
        return "?", "?", "?", "?"
    shown = f"1/{round(1.0 / dt)}" if abs(1.0 / dt - round(1.0 / dt)) < 1e-6 else f"{dt:.3g}"
    return cfg["integrator"], shown, steps, scene.num_particles


def run_script(path, argv=None):
    """What a scene script does when executed: ``python scenes/NAME.py [render options]``."""
    parser = argparse.ArgumentParser(prog=os.path.basename(path),
                                     description=describe(path))
    _render_parser(parser)
    args = parser.parse_args(argv)
    sys.exit(_guarded(lambda: render_script(path, args), args.verbose))


if __name__ == "__main__":
    sys.exit(main())
