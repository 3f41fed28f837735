"""tcloth: a mass-spring cloth and particle-system sandbox on Taichi."""
from .errors import InstabilityError, SceneError, StaleSimulatorError
from .runtime import init
from .scene import Cloth, Rope, Scene
from .simulator import Simulator

__version__ = "0.1.0"

__all__ = ["init", "Scene", "Cloth", "Rope", "Simulator", "SceneError", "InstabilityError",
           "StaleSimulatorError", "__version__"]
