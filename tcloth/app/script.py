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
A dt given on the command line (``with_options``) without steps_per_frame (``--steps-per-frame``,
the viewer's ``--substeps``) drops the script's steps_per_frame: its steps fill a frame.
"""
import ast
import importlib.util
import inspect
import math
import numbers
import os
import re

from ..errors import SceneError

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


def literal(text):
    """A ``--set`` (or a benchmark's ``--config``) VALUE: a Python literal (a number,
    [64, 64], "text", True), or else the text itself, a string."""
    text = text.strip()
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


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
        params[name] = literal(text)
    return params


def build_scene(module, path, params=None):
    """The Scene of a loaded script's build(**params), or ScriptError naming the script."""
    from ..scene.scene import Scene
    try:
        scene = module.build(**(params or {}))
    except SceneError:
        raise
    except Exception as e:
        call = ", ".join(f"{k}={v!r}" for k, v in (params or {}).items())
        raise ScriptError(f"scene script {path!r}: build({call}) raised "
                          f"{type(e).__name__}: {e}") from e
    if not isinstance(scene, Scene):
        raise ScriptError(f"scene script {path!r}: build() must return a tcloth.Scene "
                          f"(got {type(scene).__name__})")
    return scene


def with_options(cfg, path, options):
    """A merged CONFIG with the command line's values in it, every timing value checked.

    Args:
        cfg: the script's CONFIG merged over DEFAULTS (``load_script``).
        options: {CONFIG key: (option, value)}, value None where the option was not given,
            e.g. {"dt": ("--dt", 0.01), "steps_per_frame": ("--substeps", None)}.
    Returns:
        the new dict. A dt given without steps_per_frame drops the script's
        steps_per_frame, so that as many steps of that dt as fill a frame follow
        (``timing``: round(1 / (fps dt)), at least 1): a frame stays 1/fps s of simulated
        time, where the script's count was made for its own dt.
    Raises:
        ScriptError naming the option and its value (or the CONFIG key) when dt is not a
        finite time > 0, or steps_per_frame or frames a whole number >= 1, or fps finite
        and > 0 (``check_timing``).
    """
    merged, named = dict(cfg), {}
    for key, (option, value) in options.items():
        if value is not None:
            merged[key], named[key] = value, option
    if "dt" in named and "steps_per_frame" not in named:
        merged["steps_per_frame"] = None
    check_timing(merged, path, named)
    return merged


def check_timing(cfg, path, named=None):
    """ScriptError unless a merged CONFIG's dt (None or finite > 0, s), steps_per_frame
    (None or a whole number >= 1), frames (a whole number >= 1) and fps (finite > 0) can
    run; the message names the command-line option a value came from (``named``: {key:
    option}), else the script's CONFIG key, and the value."""
    named = named or {}

    def refuse(key, rule):
        where = (named[key] if key in named else
                 f"scene script {path!r}: CONFIG[{key!r}] =")
        raise ScriptError(f"{where} {cfg[key]!r}: must be {rule}")

    def whole(value):
        return isinstance(value, numbers.Integral) and not isinstance(value, bool)

    def positive(value):
        return (isinstance(value, numbers.Real) and not isinstance(value, bool)
                and math.isfinite(value) and value > 0)

    if cfg["dt"] is not None and not positive(cfg["dt"]):
        refuse("dt", "a time step in seconds, finite and > 0")
    if cfg["steps_per_frame"] is not None and not (whole(cfg["steps_per_frame"])
                                                   and cfg["steps_per_frame"] >= 1):
        refuse("steps_per_frame", "a whole number of steps a frame, >= 1")
    if not (whole(cfg["frames"]) and cfg["frames"] >= 1):
        refuse("frames", "a whole number of frames, >= 1")
    if not positive(cfg["fps"]):
        refuse("fps", "frames per second, finite and > 0")


def timing(cfg, scene):
    """(dt, steps_per_frame) for a merged CONFIG: the script's own where it gives them,
    else the rule in this module's docstring."""
    from ..scene.stability import gershgorin_dt
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
    """The first sentence of a script's docstring (of its first paragraph, on one line,
    whole however its lines wrap), read without running it."""
    try:
        with open(path) as f:
            doc = ast.get_docstring(ast.parse(f.read())) or ""
    except (OSError, SyntaxError) as e:
        return f"(unreadable: {e})"
    paragraph = " ".join(doc.strip().split("\n\n")[0].split()).replace("``", "")
    if not paragraph:
        return "(no description)"
    # a sentence ends at . ! or ? before a capital letter or the paragraph's end
    sentence = re.match(r"(.+?[.!?])(?:\s+(?=[A-Z])|$)", paragraph)
    return sentence.group(1) if sentence else paragraph
