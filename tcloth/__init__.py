"""tcloth: a mass-spring cloth and particle-system sandbox on Taichi."""
import os

# Taichi prints a version banner on import; tcloth's output (e.g. `tcloth list`) stays clean
# unless the user asks for it.
os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "False")

from . import cli, features  # noqa: E402,F401  (after the environment default above)
from .errors import (ConvergenceWarning, DeviceWarning, InstabilityError, SceneError,
                     StaleSimulatorError)
from .mesh import export_mesh, write_obj, write_ply
from .camera import Camera
from .render import Renderer, render
from .runtime import device, init
from .builders import Cloth, MeshCloth, Rope
from .fabric import Fabric
from .objfile import load_obj
from .scene import Scene
from .simulator import Simulator
from .video import record, write_png
from .version import __version__
from .viewer import view


__all__ = ["cli", "init", "device", "Scene", "Cloth", "MeshCloth", "Rope", "Fabric", "load_obj", "Simulator", "SceneError", "InstabilityError", "ConvergenceWarning", "DeviceWarning",
           "StaleSimulatorError", "Camera", "Renderer", "render", "record", "write_png",
           "export_mesh", "write_obj", "write_ply", "view",
           "__version__"]
