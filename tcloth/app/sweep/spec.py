"""A sweep's spec (TOML or a dict): validated in full before anything runs, then expanded
into cases (every combination of the ``[vary]`` values).

Keys (top level):
    scene      path of a scene script (``build(**params)``); a relative path is taken from
               the current folder, else from the spec file's folder.
    duration   simulated seconds per case, > 0.
    build      fixed build parameters (a table).
    vary       key -> list of values; every combination is one case. A key is a simulator
               setting (integrator, dt, precision, options) or a build parameter. A list of
               tables varies several settings together (one case per table; a table may
               name itself with ``label``).
    reference  integrator, dt, precision, options of the run that ``error`` is measured
               against (the RMS distance over particles at each case's end time).
    integrator, dt, precision, options   fixed simulator settings (default: the script's
               CONFIG, precision "f32"). A case's steps are not split where they fail
               (``Simulator(split=False)``, unless its options say ``split``): a case
               studies its own dt.
    arch       Taichi arch of the cases (default "cpu").
    energy_limit   J: a case whose total energy grows by more than this counts as unstable
               (default: none, only a non-finite or unbounded state does).
    max_steps  at most this many steps per case (the case then ends before ``duration``).
    samples    how many times during a case the strain is sampled for ``max_strain``
               (default 20).
"""
import hashlib
import inspect
import itertools
import json
import math
import os

from ..script import ScriptError, build_scene, load_script, timing
from ...errors import SceneError
from ...integrators import INTEGRATORS

SETTINGS = ("integrator", "dt", "precision", "options")
TOP_KEYS = {"scene", "duration", "build", "vary", "reference", "arch", "energy_limit",
            "max_steps", "samples"} | set(SETTINGS)
PRECISIONS = ("f32", "f64")
ARCHS = ("cpu", "gpu", "cuda", "vulkan", "metal", "auto")


class SpecError(SceneError):
    """A sweep spec that cannot run; the message names the key and the value."""


def load_spec(source):
    """A validated ``Spec`` from a TOML file path or a dict."""
    if isinstance(source, dict):
        return Spec(source, folder=os.getcwd())
    path = os.fspath(source)
    if not os.path.isfile(path):
        raise SpecError(f"sweep spec {path!r} does not exist")
    try:
        import tomllib
    except ModuleNotFoundError:
        import tomli as tomllib
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise SpecError(f"sweep spec {path!r} is not valid TOML: {e}") from None
    return Spec(data, folder=os.path.dirname(os.path.abspath(path)))


def _number(key, value, positive=True):
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or not math.isfinite(value) or (positive and value <= 0):
        raise SpecError(f"{key} must be a {'positive ' if positive else ''}finite number "
                        f"(got {value!r})")
    return float(value)


def count(key, value, error=SpecError):
    """``value`` if it is an integer >= 1, else ``error`` naming ``key``."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise error(f"{key} must be an integer >= 1 (got {value!r})")
    return value


def _check_setting(key, name, value):
    """A simulator setting's value in canonical form, or SpecError naming ``key``."""
    if name == "integrator":
        if value not in INTEGRATORS:
            raise SpecError(f"{key}: unknown integrator {value!r} "
                            f"(known: {', '.join(sorted(INTEGRATORS))})")
        return value
    if name == "dt":
        return _number(key, value)
    if name == "precision":
        if value not in PRECISIONS:
            raise SpecError(f"{key} must be 'f32' or 'f64' (got {value!r})")
        return value
    if not isinstance(value, dict):
        raise SpecError(f"{key} must be a table of integrator options (got {value!r})")
    return dict(value)


def _digest(obj):
    return hashlib.sha1(json.dumps(obj, sort_keys=True, default=repr).encode()).hexdigest()[:16]


class Spec:
    """A validated sweep spec: ``cases()`` lists its cases, ``reference`` its reference
    settings (or None)."""

    def __init__(self, data, folder):
        unknown = sorted(set(data) - TOP_KEYS)
        if unknown:
            raise SpecError(f"unknown key {unknown[0]!r} in the sweep spec "
                            f"(known: {', '.join(sorted(TOP_KEYS))})")
        self.data = data
        for key in ("scene", "duration"):
            if key not in data:
                raise SpecError(f"the sweep spec needs {key!r}")
        self.scene = self._scene_path(data["scene"], folder)
        with open(self.scene, "rb") as f:
            self.scene_digest = hashlib.sha1(f.read()).hexdigest()
        try:
            module, config = load_script(self.scene)
        except ScriptError as e:
            raise SpecError(str(e)) from None
        self.duration = _number("duration", data["duration"])
        self.arch = data.get("arch", "cpu")
        if self.arch not in ARCHS:
            raise SpecError(f"arch must be one of {', '.join(ARCHS)} (got {self.arch!r})")
        self.energy_limit = (None if data.get("energy_limit") is None
                             else _number("energy_limit", data["energy_limit"], False))
        self.max_steps = data.get("max_steps")
        if self.max_steps is not None:
            count("max_steps", self.max_steps)
        self.samples = count("samples", data.get("samples", 20))
        self._parameters = self._build_parameters(module)
        self.settings = {"integrator": config["integrator"], "dt": config["dt"],
                         "precision": "f32", "options": dict(config["options"])}
        for name in SETTINGS:
            if name in data:
                self.settings[name] = _check_setting(name, name, data[name])
        if not isinstance(data.get("build", {}), dict):
            raise SpecError(f"build must be a table of build parameters (got {data['build']!r})")
        self.build = dict(data.get("build", {}))
        for name in self.build:
            self._check_parameter(f"build.{name}", name)
        if self.settings["dt"] is None:         # the script's own rule (script.timing)
            try:
                scene = build_scene(module, self.scene, self.build)
            except ScriptError as e:
                raise SpecError(str(e)) from None
            self.settings["dt"] = timing({**config, **self.settings}, scene)[0]
        self.vary = self._vary(data.get("vary", {}))
        self.reference = self._reference(data.get("reference"))

    @staticmethod
    def _scene_path(value, folder):
        if not isinstance(value, str) or not value:
            raise SpecError(f"scene must be the path of a scene script (got {value!r})")
        for base in (os.getcwd(), folder):
            path = os.path.abspath(os.path.join(base, value))
            if os.path.isfile(path):
                return path
        raise SpecError(f"scene {value!r}: no such scene script (looked in {os.getcwd()!r} "
                        f"and {folder!r})")

    @staticmethod
    def _build_parameters(module):
        """Names build() accepts, or None where it takes **kwargs."""
        params = inspect.signature(module.build).parameters.values()
        if any(p.kind is p.VAR_KEYWORD for p in params):
            return None
        return {p.name for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}

    def _check_parameter(self, key, name):
        if self._parameters is not None and name not in self._parameters:
            raise SpecError(f"{key}: the scene's build() takes no parameter {name!r} "
                            f"(it takes: {', '.join(sorted(self._parameters)) or 'none'})")

    def _check_value(self, key, name, value):
        if name in SETTINGS:
            return _check_setting(key, name, value)
        self._check_parameter(key, name)
        return value

    def _vary(self, vary):
        if not isinstance(vary, dict):
            raise SpecError(f"vary must be a table of key = [values] (got {vary!r})")
        out, self.grouped = {}, set()
        for name, values in vary.items():
            key = f"vary.{name}"
            if not isinstance(values, list) or not values:
                raise SpecError(f"{key} must be a non-empty list of values (got {values!r})")
            if name not in SETTINGS and not all(isinstance(v, dict) for v in values):
                self._check_parameter(key, name)
            if all(isinstance(v, dict) for v in values):
                out[name] = [self._group(f"{key}[{i}]", v) for i, v in enumerate(values)]
                self.grouped.add(name)
            else:
                out[name] = [({name: self._check_value(f"{key}[{i}]", name, v)}, v)
                             for i, v in enumerate(values)]
        return out

    def _group(self, key, table):
        """A table of several settings varied together: (values, label)."""
        values = {}
        for name, value in table.items():
            if name != "label":
                values[name] = self._check_value(f"{key}.{name}", name, value)
        label = table.get("label", ", ".join(f"{k}={v}" for k, v in values.items()))
        if not isinstance(label, str):
            raise SpecError(f"{key}.label must be a string (got {label!r})")
        return values, label

    def _reference(self, table):
        if table is None:
            return None
        if not isinstance(table, dict):
            raise SpecError(f"reference must be a table (got {table!r})")
        unknown = sorted(set(table) - set(SETTINGS))
        if unknown:
            raise SpecError(f"unknown key {unknown[0]!r} in reference "
                            f"(known: {', '.join(SETTINGS)})")
        ref = {"integrator": "rk4", "precision": "f64", "options": {}}
        if "dt" not in table:
            raise SpecError("reference needs dt")
        for name, value in table.items():
            ref[name] = _check_setting(f"reference.{name}", name, value)
        return ref

    def cases(self):
        """Every combination of the varied values, in spec order: dicts with ``id``,
        ``values`` (varied key -> value as written, for the table), ``settings``,
        ``build``, ``steps``, ``t_end`` and ``reference_id`` (None without a reference)."""
        out = []
        for combo in itertools.product(*self.vary.values()):
            settings, build, values = dict(self.settings), dict(self.build), {}
            for name, (assigned, shown) in zip(self.vary, combo):
                values[name] = shown
                for key, value in assigned.items():
                    (settings if key in SETTINGS else build)[key] = value
            steps = max(1, round(self.duration / settings["dt"]))
            if self.max_steps is not None:
                steps = min(steps, self.max_steps)
            case = {"scene": self.scene, "arch": self.arch, "settings": settings,
                    "build": build, "steps": steps, "t_end": steps * settings["dt"],
                    "energy_limit": self.energy_limit, "samples": self.samples,
                    "values": values}
            case["group"] = _digest([self.scene_digest, self.arch, build,
                                     {k: v for k, v in settings.items() if k != "dt"}])
            case["reference_id"] = (None if self.reference is None
                                    else _digest([self.scene_digest, build, self.reference]))
            case["id"] = _digest([self.scene_digest, case["group"], settings, steps,
                                  self.energy_limit, self.samples, case["reference_id"]])
            out.append(case)
        return out
