"""The written protocols: terms declare their capabilities (terms/base.py), integrators
their live options (integrators/base.py); nothing is found by hasattr or set from outside."""
import numpy as np
import pytest

import tcloth
from tcloth import terms
from test_pressure import balloon, icosahedron
from tcloth.terms.base import CAPABILITIES, Term


def test_every_term_declares_what_it_gives():
    """Each term class's declared capabilities have their methods, and no class gives all
    of a capability's methods without declaring it (checked again here, class by class,
    since the check runs once, when a class is made)."""
    for cls in terms.TERMS:
        for capability, methods in CAPABILITIES.items():
            given = all(callable(getattr(cls, m, None)) for m in methods)
            assert given == cls.has(capability), (cls.__name__, capability)
    assert terms.Bending.has("local_system") and terms.Membrane.has("local_system")
    assert not terms.Pressure.has("local_system") and terms.Pressure.has("constraints")
    assert terms.Colliders.has("contact_planes") and terms.SelfContact.has("projection")


def test_a_term_that_hides_or_overstates_a_capability_is_refused():
    with pytest.raises(TypeError, match="does not declare 'local_system'"):
        type("Hidden", (Term,), {"local_system": lambda self: None,
                                 "local_energy": lambda self: None})
    with pytest.raises(TypeError, match="provides 'constant_matrix' without constant_matrix"):
        type("Overstated", (Term,), {"provides": frozenset({"constant_matrix"})})
    with pytest.raises(TypeError, match="unknown capabilities"):
        type("Unknown", (Term,), {"provides": frozenset({"telepathy"})})
    with pytest.raises(ValueError, match="no capability 'telepathy'"):
        Term.has("telepathy")


def test_terms_take_the_options_they_declare_when_built(f64):
    """build() gives each term only the options it declares: the membrane and pressure
    take exact, the pressure jacobi; the others are built as before."""
    scene = balloon(*icosahedron(0.1), pressure=100.0, ambient=1e4)
    scene.set_membrane(100.0, 10.0)
    model = tcloth.Simulator(scene, "symplectic_euler").model
    built = {type(t).__name__: t for t in terms.build(model, exact=True, jacobi=True)}
    assert built["Membrane"].exact and built["Pressure"].exact and built["Pressure"].jacobi
    plain = {type(t).__name__: t for t in terms.build(model)}
    assert not plain["Membrane"].exact and not plain["Pressure"].jacobi


def _cloth():
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(8, 8), size=(0.5, 0.5), center=(0, 0.5, 0),
                    structural=(500.0, 0.05), shear=(50.0, 0.01), flexion=(5.0, 0.001))
    return scene


@pytest.mark.slow_cases("vbd")
@pytest.mark.parametrize("integrator", ["vbd", "xpbd"])
def test_a_live_option_change_equals_a_new_integrator(f32, integrator):
    """Changing iterations through set_integrator_options keeps the kernels and gives,
    bit for bit, the steps of an integrator built with the new count, in single steps and
    in a batch (whose kernel compiles the count in, so it compiles again). VBD guesses
    from inertia here: a new integrator has no last step's forces for the adaptive
    guess."""
    options = {"initial_guess": "inertia"} if integrator == "vbd" else {}
    changed = tcloth.Simulator(_cloth(), integrator, dt=1 / 60, iterations=4, **options)
    changed.step(3)
    changed.set_integrator_options(iterations=7)
    with pytest.raises(TypeError):
        changed.integrator.options["iterations"] = 2
    fresh = tcloth.Simulator(_cloth(), integrator, dt=1 / 60, iterations=4, **options)
    fresh.step(3)
    fresh.set_integrator(integrator, iterations=7, **options)
    for sim in (changed, fresh):
        sim.step()
        sim.step(5)
    assert changed.integrator.options["iterations"] == 7
    assert np.array_equal(changed.positions(), fresh.positions())
    assert np.array_equal(changed.velocities(), fresh.velocities())


def test_an_option_that_shapes_the_integrator_is_refused_by_name(f32):
    sim = tcloth.Simulator(_cloth(), "vbd", dt=1 / 60)
    with pytest.raises(tcloth.SceneError, match=r"'bounds' shapes what the integrator built: "
                                                r"give it to Simulator.set_integrator\('vbd'"):
        sim.set_integrator_options(bounds=True)
    with pytest.raises(tcloth.SceneError, match="unknown option 'iteration' for integrator"):
        sim.set_integrator_options(iteration=3)
    with pytest.raises(tcloth.SceneError, match="iterations must be an int >= 1"):
        sim.set_integrator_options(iterations=0)
    assert sim.integrator.options["iterations"] == 10       # the refused change undone
