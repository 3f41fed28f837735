"""Scene scripts: loading one, its CONFIG, its build parameters, and the step it runs at.

A scene script defines ``build(**params) -> tcloth.Scene`` and a dict ``CONFIG`` with any of
the keys of ``DEFAULTS`` (and ``description``). The command line (``cli.py``) and sweeps
(``sweep/``) both read scripts through this module.

The step (``timing``): a script that gives no ``dt`` gets one from its scene, and one that
gives no ``steps_per_frame`` gets as many steps as fill a frame of 1/fps seconds, so that
the video plays in real time.
  - Explicit integrators: dt = DT_SAFETY (forward Euler: FORWARD_EULER_SAFETY) times
    ``stability.gershgorin_dt(scene)``, a lower bound on symplectic Euler's stability
    limit from the stiffest springs and contacts (2 / omega, omega^2 at most the largest
    row sum of M^-1/2 K M^-1/2), then shortened so that a whole number of steps fills
    a frame (with steps_per_frame given: that bound or 1/(fps steps), the shorter).
  - Implicit integrators (stable at any dt): IMPLICIT_STEPS_PER_FRAME steps a frame, or
    steps_per_frame.
"""
import ast
import importlib.util
import inspect
import math
import os

from .errors import SceneError

DEFAULTS = {"integrator": "symplectic_euler", "dt": None, "steps_per_frame": None,
            "frames": 120, "fps": 30, "camera": None, "width": 640, "height": 480,
            "supersample": 2, "options": {}, "render": {}, "precision": "f32"}
EXPLICIT = ("forward_euler", "symplectic_euler", "verlet", "rk4")
DT_SAFETY = 0.5
FORWARD_EULER_SAFETY = 0.1
IMPLICIT_STEPS_PER_FRAME = 4


class ScriptError(Exception):
    """A scene script that cannot be used; the message names the path."""


def load_script(path):
    """Import a scene script; returns (module, CONFIG merged over DEFAULTS)."""
    if not os.path.isfile(path):
        raise ScriptError(f"scene script {path!r} does not exist")
    name = "tcloth_scene_" + os.path.splitext(os.path.basename(path))[0]
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except Exception as e:
        raise ScriptError(f"scene script {path!r} raised {type(e).__name__}: {e}") from e
    if not callable(getattr(module, "build", None)):
        raise ScriptError(f"scene script {path!r} defines no build(**params) function")
    config = getattr(module, "CONFIG", {})
    if not isinstance(config, dict):
        raise ScriptError(f"scene script {path!r}: CONFIG must be a dict "
                          f"(got {type(config).__name__})")
    unknown = sorted(set(config) - set(DEFAULTS) - {"description"})
    if unknown:
        raise ScriptError(f"scene script {path!r}: unknown CONFIG key {unknown[0]!r} "
                          f"(known: {sorted(DEFAULTS)})")
    return module, {**DEFAULTS, **config}


def build_parameters(module):
    """{name: default} of a script's build() keyword parameters."""
    return {name: p.default for name, p in inspect.signature(module.build).parameters.items()
            if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}


def parse_settings(module, path, settings):
    """{name: value} from ``--set NAME=VALUE`` strings: each NAME a build() parameter of the
    script, each VALUE a Python literal (a number, [64, 64], "text", True) or else a
    string."""
    known = build_parameters(module)
    params = {}
    for item in settings or ():
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ScriptError(f"--set {item!r}: expected NAME=VALUE")
        if name not in known:
            raise ScriptError(f"--set {name}: scene script {path!r} has no build parameter "
                              f"{name!r} (its parameters: {', '.join(known) or 'none'})")
        try:
            value = ast.literal_eval(text.strip())
        except (ValueError, SyntaxError):
            value = text.strip()
        params[name] = value
    return params


def build_scene(module, path, params=None):
    """The Scene of a loaded script's build(**params), or ScriptError naming the script."""
    from .scene import Scene
    try:
        scene = module.build(**(params or {}))
    except SceneError:
        raise
    except Exception as e:
        raise ScriptError(f"scene script {path!r}: build() raised {type(e).__name__}: {e}") from e
    if not isinstance(scene, Scene):
        raise ScriptError(f"scene script {path!r}: build() must return a tcloth.Scene "
                          f"(got {type(scene).__name__})")
    return scene


def timing(cfg, scene):
    """(dt, steps_per_frame) for a merged CONFIG: the script's own where it gives them,
    else the rule in this module's docstring."""
    from .stability import gershgorin_dt
    frame = 1.0 / cfg["fps"]
    dt, steps = cfg["dt"], cfg["steps_per_frame"]
    if dt is None:
        if cfg["integrator"] not in EXPLICIT:
            steps = steps or IMPLICIT_STEPS_PER_FRAME
            return frame / steps, steps
        safety = (FORWARD_EULER_SAFETY if cfg["integrator"] == "forward_euler"
                  else DT_SAFETY)
        limit = safety * gershgorin_dt(scene)
        if steps:
            return min(frame / steps, limit), steps
        steps = max(1, math.ceil(frame / limit))
        return frame / steps, steps
    return dt, steps or max(1, round(frame / dt))


def describe(path):
    """The first line of a script's docstring, read without running it."""
    try:
        with open(path) as f:
            doc = ast.get_docstring(ast.parse(f.read())) or ""
    except (OSError, SyntaxError) as e:
        return f"(unreadable: {e})"
    return doc.strip().splitlines()[0] if doc.strip() else "(no description)"
