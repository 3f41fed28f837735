"""tcloth: a mass-spring cloth and particle-system sandbox on Taichi."""
from . import cli
from .errors import InstabilityError, SceneError, StaleSimulatorError
from .render import Camera, Renderer, render
from .runtime import init
from .scene import Cloth, Rope, Scene
from .simulator import Simulator
from .video import record, write_png

__version__ = "0.1.0"

__all__ = ["init", "Scene", "Cloth", "Rope", "Simulator", "SceneError", "InstabilityError",
           "StaleSimulatorError", "Camera", "Renderer", "render", "record", "write_png",
           "__version__"]
