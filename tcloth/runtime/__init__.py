"""Taichi initialisation: architecture, precision and the runtime generation.

``init`` may be called again; every call starts a new *generation*, and objects that
hold Taichi fields from an earlier generation refuse to run (``StaleSimulatorError``).
The package also holds what the initialisation uses: the caches that make Taichi's
frontend cheaper to run again (``frontend.py``) and the Vulkan device probe that names
what ``arch="vulkan"`` runs on (``vulkan_probe.py``).
"""
from typing import Any, Optional

import os
import warnings

import numpy as np
import taichi as ti

from . import frontend
from ..errors import DeviceWarning, SceneError, StaleSimulatorError

frontend.install()

_ARCHS = {
    "auto": lambda: None,
    "cpu": lambda: ti.cpu,
    "gpu": lambda: ti.gpu,
    "cuda": lambda: ti.cuda,
    "vulkan": lambda: ti.vulkan,
    "metal": lambda: ti.metal,
}
_PRECISIONS = {"f32": ti.f32, "f64": ti.f64}

# Below this many items a CPU loop runs on one thread: starting Taichi's thread pool costs
# more than a second thread gains (docs/benchmarks.md, "One thread against the thread pool").
SERIAL_BELOW = 131072


class _Runtime:
    generation = 0
    initialised = False
    real = ti.f32
    precision = "f32"
    arch_name = "cpu"
    device = "the CPU"
    serial_below = SERIAL_BELOW


def init(arch: str = "cpu", precision: str = "f32", serial_below: Optional[int] = None,
         quick_compile: Optional[bool] = None, **kwargs: Any) -> None:
    """(Re-)initialise Taichi for tcloth.

    Args:
        arch: "auto" | "cpu" | "gpu" | "cuda" | "vulkan" | "metal".
        precision: "f32" (default, fast) or "f64" (accuracy studies).
        serial_below: on CPUs, loops over fewer items run on one thread (default
            SERIAL_BELOW; see ``serial``). 0 makes every loop parallel.
        quick_compile: compile with Taichi's control-flow-graph optimisation off
            (``cfg_optimization=False``): the same numbers bit for bit, half the time to
            compile a scene with contact and slower contact steps (the fold's first
            frame, compiled afresh: 98 s, 47 s quick; its frames 1.4x as long). For
            short runs, whose time is compiling: the test suite sets it. None reads
            TCLOTH_QUICK_COMPILE ("0" or "1"; default 0).
        **kwargs: passed on to ``ti.init`` (e.g. ``kernel_profiler=True``).

    Taichi compiles with ``fast_math=False`` unless ``fast_math=True`` is given: IEEE
    arithmetic with no reassociation and no contraction into fused multiply-adds, so that
    the same operations give the same numbers wherever a ``ti.func`` is inlined (a batch of
    substeps against single steps, a checkpoint's continuation) and on CPUs with other
    vector units (AVX2 against AVX-512). What it costs: docs/benchmarks.md, "Fast math and
    the scene snapshots".

    A request for a GPU that lands on the CPU (Taichi falls back without a word) or on a
    software Vulkan driver warns (``tcloth.DeviceWarning``); ``device()`` says what it
    runs on.
    """
    if arch not in _ARCHS:
        raise SceneError(f"arch must be one of {sorted(_ARCHS)} (got {arch!r})")
    if precision not in _PRECISIONS:
        raise SceneError(f"precision must be 'f32' or 'f64' (got {precision!r})")
    if serial_below is not None:
        if isinstance(serial_below, bool) or not isinstance(serial_below, int) \
                or serial_below < 0:
            raise SceneError(f"serial_below must be an integer >= 0 (got {serial_below!r})")
        _Runtime.serial_below = serial_below
    real = _PRECISIONS[precision]
    ti_arch = _ARCHS[arch]()
    kwargs.setdefault("log_level", ti.WARN)
    kwargs.setdefault("fast_math", False)
    if _flag("quick_compile", quick_compile, "TCLOTH_QUICK_COMPILE", False):
        kwargs.setdefault("cfg_optimization", False)
    if ti_arch is None:
        ti.init(default_fp=real, **kwargs)
    else:
        ti.init(arch=ti_arch, default_fp=real, **kwargs)
    _Runtime.generation += 1
    _Runtime.initialised = True
    _Runtime.real = real
    _Runtime.precision = precision
    _Runtime.arch_name = ti.lang.impl.current_cfg().arch.name
    _Runtime.device = _device()
    gpu_asked = arch in ("gpu", "cuda", "vulkan", "metal")
    if gpu_asked and cpu():
        warnings.warn(f"arch={arch!r} asked for a GPU, and none that Taichi can use is here: "
                      f"running on {_Runtime.device}", DeviceWarning, stacklevel=2)
    elif "software" in _Runtime.device:
        warnings.warn(f"arch={arch!r} runs on {_Runtime.device}, which works on the CPU far "
                      "slower than arch='cpu'", DeviceWarning, stacklevel=2)
    return _Runtime.generation


def _device():
    """What the current arch runs on, in words."""
    name = _Runtime.arch_name
    if cpu():
        return f"the CPU ({name}, {ti.lang.impl.current_cfg().cpu_max_num_threads} threads)"
    if name == "vulkan":
        from .vulkan_probe import devices
        found = devices()
        if found and all(kind == "CPU" for _, kind in found):
            return f"Vulkan on {found[0][0]} (a software driver)"
        gpus = [n for n, kind in found if kind != "CPU"]
        return f"Vulkan on {gpus[0]}" if gpus else "Vulkan"
    return {"cuda": "CUDA", "metal": "Metal", "opengl": "OpenGL"}.get(name, name)


def device():
    """What tcloth runs on, in words (e.g. "the CPU (x64, 2 threads)", "CUDA",
    "Vulkan on llvmpipe (...) (a software driver)")."""
    ensure_init()
    return _Runtime.device


def ensure_init():
    """Initialise with defaults unless somebody already did."""
    if not _Runtime.initialised:
        init()
    return _Runtime.generation


def real():
    """The Taichi float type of the current precision."""
    return _Runtime.real


def precision():
    """"f32" or "f64"."""
    return _Runtime.precision


def serial_below():
    """Loops over fewer items than this run on one CPU thread (``init(serial_below=...)``)."""
    return _Runtime.serial_below


def numpy_real():
    return "float64" if _Runtime.precision == "f64" else "float32"


def arch_name():
    return _Runtime.arch_name


def generation():
    return _Runtime.generation


def accumulator():
    """Float type for reductions: f64 where the backend has it."""
    return ti.f64 if _Runtime.arch_name in ("x64", "arm64", "cuda") else _Runtime.real


def cpu():
    """True on CPU backends."""
    return _Runtime.arch_name in ("x64", "arm64")


def serial(field, work=1):
    """True where a loop over ``field`` should run on one CPU thread: below
    ``init(serial_below=...)`` items (default SERIAL_BELOW) the thread pool's start-up and
    hand-offs cost more than the second thread gains; an item that costs ``work`` simple
    ones (a mesh collider's hierarchy query: ``meshstore.QUERY_WORK``) counts as that many.
    Evaluated at compile time (``ti.static``), so it is fixed when a simulator's kernels
    compile; never on GPUs."""
    return serial_count(field.shape[0] * work)


def serial_count(items):
    """``serial`` for a loop over ``items`` items."""
    return cpu() and items < _Runtime.serial_below


@ti.func
def jacobi_zero(dx, hits):
    """A Jacobi pass's accumulators zeroed: each particle's summed moves dx and their
    count hits."""
    ti.loop_config(serialize=ti.static(serial(dx)))
    for p in range(dx.shape[0]):
        dx[p] = ti.Vector.zero(float, 3)
        hits[p] = 0


@ti.func
def jacobi_apply(x, dx, hits):
    """Each particle moved by the mean of the moves a Jacobi pass summed for it."""
    ti.loop_config(serialize=ti.static(serial(dx)))
    for p in range(dx.shape[0]):
        if hits[p] > 0:
            x[p] += dx[p] / hits[p]


@ti.kernel
def _copy_out(src: ti.template(), out: ti.types.ndarray()):
    ti.loop_config(serialize=ti.static(serial(src)))
    for p in range(src.shape[0]):
        for c in ti.static(range(src.n)):
            out[p, c] = src[p][c]


def to_numpy(field):
    """NumPy copy of a vector field of shape (N,), as an (N, components) array. On CPUs one
    launch that writes into the new array, which costs less than ``Field.to_numpy`` (it
    also synchronises and handles every layout) for a frame's positions
    (docs/benchmarks.md, "Per frame from Python")."""
    if not cpu():
        return field.to_numpy()
    out = np.empty((field.shape[0], field.n), dtype=np.float64 if field.dtype == ti.f64
                   else np.float32)
    _copy_out(field, out)
    return out


def compilations():
    """How many kernel instances Taichi has compiled in this process so far (None on
    another Taichi than 1.7); the difference across a frame is what it compiled."""
    return frontend.compilations()


def check_generation(gen, what="simulator"):
    if gen != _Runtime.generation:
        raise StaleSimulatorError(
            f"this {what} was made before tcloth.init() was called again; its Taichi "
            "fields are gone. Build a new tcloth.Simulator from the scene.")


def compile_ahead(value):
    """``Simulator(compile_ahead=...)`` as a bool: None reads TCLOTH_COMPILE_AHEAD."""
    return _flag("compile_ahead", value, "TCLOTH_COMPILE_AHEAD", True)


def _flag(name, value, variable, default):
    """Option ``name`` as a bool: True or False as given, None read from the environment
    variable ``variable`` ("0" or "1"; ``default`` where it is unset)."""
    if value is None:
        text = os.environ.get(variable, "1" if default else "0")
        if text not in ("0", "1"):
            raise SceneError(f"{variable} must be 0 or 1 (got {text!r})")
        return text == "1"
    if not isinstance(value, bool):
        raise SceneError(f"{name} must be True, False or None (got {value!r})")
    return value
