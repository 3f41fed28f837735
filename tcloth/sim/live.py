"""The simulator's parameters that change while it runs (``LiveParameters``, a part of
``Simulator``): gravity, drag, masses, springs, wind, colliders and the live features.
Each change goes into the scene, is checked there, and reaches the model's fields and the
integrator's caches through ``_parameters_changed``; the energy budget takes a new
baseline. Nothing is compiled again."""
from ..errors import SceneError
from ..features import FEATURES
from ..validate import as_index, as_scalar, as_vec3


class LiveParameters:
    """``Simulator``'s setters of live parameters (it provides scene, model, settings,
    integrator, ``_check`` and ``_rebase``)."""

    def set_gravity(self, gravity):
        """Gravity (3,), m/s^2, from now on."""
        self.scene.gravity = as_vec3("gravity", gravity)
        self._parameters_changed()

    def set_air_drag(self, air_drag):
        """The viscous air drag c >= 0 (N s/m): force -c v on every particle, from now on."""
        self.scene.air_drag = as_scalar("air_drag", air_drag, minimum=0.0)
        self._parameters_changed()

    def set_air_damping(self, air_damping):
        """The mass-proportional air damping gamma >= 0 (1/s): force -gamma m_p v on
        particle p, the same at every resolution, from now on."""
        self.scene.air_damping = as_scalar("air_damping", air_damping, minimum=0.0)
        self._parameters_changed()

    def set_masses(self, masses):
        """Every particle's mass (N,), kg, > 0, from now on (``Scene.set_masses``: the air
        damping, the membrane's and the colliders' damping follow it; the springs' k_d
        stay)."""
        self.scene.set_masses(masses)
        self._parameters_changed()

    def set_springs(self, kind, stiffness=None, damping=None):
        """Stiffness k_s (N/m) and/or damping k_d (N s/m) of every spring of one kind
        ("structural", "shear", "flexion", "custom") from now on."""
        self.scene.set_spring_parameters(kind, stiffness, damping)
        self._parameters_changed()

    def set_wind(self, velocity):
        """The mean wind velocity (3,), m/s, of a scene with wind, from now on."""
        if self.model.wind is None:
            raise SceneError("the scene has no wind (Scene.set_wind before the Simulator is "
                             "made: tcloth view --wind adds a still one)")
        self.scene.wind["velocity"] = as_vec3("velocity", velocity)
        self._parameters_changed()

    def set_collider_enabled(self, index, enabled):
        """Switch collider ``scene.colliders[index]`` on or off (off: no force, energy or
        friction; the viewer hides it)."""
        index = as_index("collider index", index, len(self.scene.colliders))
        off = set(self.settings["colliders_off"]) - {index}
        if not enabled:
            off.add(index)
        self.settings["colliders_off"] = sorted(off)
        self._parameters_changed()

    def set_feature(self, name, **changes):
        """A live scene feature's settings from now on: ``Scene.set_<name>``'s arguments
        (bending's rigidity; the membrane's stretch, shear, damping); the rest stay."""
        live = {f.name: f for f in FEATURES if f.live and getattr(self.model, f.name)}
        if name not in live:
            raise SceneError(f"no live feature {name!r} in this scene (it has {sorted(live)})")
        method, saved = getattr(self.scene, live[name].method), live[name].saved
        method(**{**saved(getattr(self.scene, name)), **changes})
        self._parameters_changed()

    def set_collider(self, index, friction=None, stiffness=None):
        """Collider ``index``'s friction mu >= 0 and/or stiffness k > 0 (N/m) from now on."""
        collider = self.scene.colliders[as_index("index", index, len(self.scene.colliders))]
        for key, value in (("friction", friction), ("stiffness", stiffness)):
            if value is not None:
                collider[key] = as_scalar(key, value, minimum=0.0, strict=key == "stiffness")
        self._parameters_changed()

    def _parameters_changed(self):
        """The scene's parameters changed: the model, the integrator and the budget
        follow."""
        self._check()
        self._fusion = None
        self.model.refresh(self.settings["colliders_off"])
        self.integrator.parameters_changed()
        self._rebase()
