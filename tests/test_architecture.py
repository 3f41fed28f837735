"""What docs/architecture.md promises about the code's shape: the imports of tcloth's
modules form no cycle (read from the source, function-level imports included), every
module reaches (directly or through the modules it imports) only its own layer and those
below (LAYERS: nothing the model reaches is a term or an integrator, nothing the scene
reaches is those or the model), moved modules' old names still import, no file is
over 500 lines and no function over 80; and that every term's feature is registered and
the model keeps each feature's data on its own object."""
import ast
import os

ROOT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tcloth")


def modules():
    """module name -> path, for every .py file under tcloth/."""
    out = {}
    for folder, _, files in os.walk(ROOT):
        for f in files:
            if f.endswith(".py"):
                path = os.path.join(folder, f)
                parts = os.path.relpath(path, os.path.dirname(ROOT))[:-3].split(os.sep)
                if parts[-1] == "__init__":
                    parts = parts[:-1]
                out[".".join(parts)] = path
    return out


def import_graph():
    """module -> the tcloth modules it imports (a package's __init__ for `from . import`
    of a name that is not a module)."""
    mods = modules()
    graph = {}
    for name, path in mods.items():
        package = name.split(".") if path.endswith("__init__.py") else name.split(".")[:-1]
        deps = set()
        for node in ast.walk(ast.parse(open(path).read())):
            if isinstance(node, ast.ImportFrom):
                base = package[:len(package) - node.level + 1] if node.level else []
                target = ".".join(base + ([node.module] if node.module else []))
                for alias in node.names:
                    full = f"{target}.{alias.name}"
                    deps.add(full if full in mods else target)
            elif isinstance(node, ast.Import):
                deps.update(alias.name for alias in node.names)
        graph[name] = {d for d in deps if d in mods and d != name}
    return graph


def cycle(graph):
    """One import cycle as a list of modules, or None (depth-first search)."""
    state, stack = {}, []

    def visit(v):
        state[v] = "open"
        stack.append(v)
        for w in sorted(graph[v]):
            if state.get(w) == "open":
                return stack[stack.index(w):] + [w]
            if w not in state:
                found = visit(w)
                if found:
                    return found
        state[v] = "done"
        stack.pop()
        return None
    for v in sorted(graph):
        if v not in state:
            found = visit(v)
            if found:
                return found
    return None


def reaches(graph, start):
    seen, todo = set(), [start]
    while todo:
        for w in graph[todo.pop()] - seen:
            seen.add(w)
            todo.append(w)
    return seen


def test_imports_form_no_cycle():
    graph = import_graph()
    assert cycle(graph) is None, " -> ".join(cycle(graph))
    # the checker sees cycles: a graph with one
    assert cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]


def test_model_and_scene_stay_upstream():
    graph = import_graph()
    below_model = reaches(graph, "tcloth.model")
    assert not sorted(m for m in below_model if m.startswith(("tcloth.terms",
                                                               "tcloth.integrators")))
    below_scene = reaches(graph, "tcloth.scene")
    assert not sorted(m for m in below_scene if m.startswith(("tcloth.terms", "tcloth.model",
                                                               "tcloth.integrators")))
    # transitive: a module reached through another counts
    assert reaches({"a": {"b"}, "b": {"c"}, "c": set()}, "a") == {"b", "c"}


# The rooms of tcloth/ by layer, lowest first (docs/architecture.md): a module reaches,
# directly or through others, only modules of its own layer and the layers before it.
# ``testing`` (the references the tests and benchmarks check a simulation with) is last:
# it may use all of tcloth, and nothing in tcloth reaches it.
LAYERS = [
    {"errors", "runtime", "validate", "version", "moved"},
    {"geometry"},
    {"scene"},
    {"contact"},
    {"features"},
    {"model"},
    {"terms"},
    {"integrators"},
    {"sim"},
    {"grad"},
    {"render"},
    {"viewer", "app", "__main__", "tcloth"},
    {"testing"},
]


def layer(module):
    """The index in LAYERS of a tcloth module's room (its first name below tcloth)."""
    parts = module.split(".")
    room = parts[1] if len(parts) > 1 else "tcloth"
    return next(k for k, rooms in enumerate(LAYERS) if room in rooms)


def test_every_module_reaches_only_its_layer_and_those_below():
    graph = import_graph()
    upward = {m: sorted(d for d in reaches(graph, m) if layer(d) > layer(m)) for m in graph}
    assert not {m: d for m, d in upward.items() if d}
    # transitive: the model reaching a term through a feature module counts
    toy = {"tcloth.model.model": {"tcloth.features.x"}, "tcloth.features.x": {"tcloth.terms.y"},
           "tcloth.terms.y": set()}
    assert [d for d in reaches(toy, "tcloth.model.model") if layer(d) > layer("tcloth.model")] \
        == ["tcloth.terms.y"]


def test_every_top_level_module_sits_in_a_room():
    """Only the base layer's modules, the package's entry points and the rooms (packages)
    sit at the top of tcloth/."""
    top = {name.split(".")[1] for name in modules() if name.count(".") >= 1}
    rooms = set().union(*LAYERS)
    assert top <= rooms, sorted(top - rooms)


def test_old_module_paths_give_the_moved_modules():
    """A moved module's old name still imports (the first layout's rooms by layer, the base
    layer's modules moved since), as the very module at its new place, saying where it
    went."""
    import importlib
    import sys
    import warnings
    from tcloth import moved
    for old, new in moved.MOVED.items():
        sys.modules.pop(old, None)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            module = importlib.import_module(old)
        assert module is importlib.import_module(new), old
        assert [str(w.message) for w in caught if w.category is DeprecationWarning] == \
            [f"{old} has moved to {new}"], old
    assert moved.new_name("tcloth.sweep.engine") == "tcloth.app.sweep.engine"
    assert moved.new_name("tcloth.terms") is None


def test_no_file_is_over_500_lines():
    long = {path: n for path in modules().values()
            if (n := sum(1 for _ in open(path))) > 500}
    assert not long, long


def test_no_function_is_over_80_lines():
    long = {f"{path}:{node.name}": node.end_lineno - node.lineno + 1
            for path in modules().values() for node in ast.walk(ast.parse(open(path).read()))
            if isinstance(node, ast.FunctionDef) and node.end_lineno - node.lineno >= 80}
    assert not long, long


def _discards(function):
    """The lines where ``function`` assigns to ``_`` (an unpacked value it drops)."""
    return [node.lineno for node in ast.walk(function) if isinstance(node, ast.Assign)
            for target in node.targets
            for name in (target.elts if isinstance(target, ast.Tuple) else [target])
            if isinstance(name, ast.Name) and name.id == "_"]


def test_no_taichi_function_drops_two_values_into_one_name():
    """Taichi gives ``_`` the type of its first value in a function; a second value of
    another type (a matrix after a scalar) is stored into that slot, which only Taichi's
    optimisation removes: with it off (``quick_compile``) LLVM aborts the process. Dropped
    values get names of their own."""
    twice = {f"{path}:{node.name}": lines for path in modules().values()
             for node in ast.walk(ast.parse(open(path).read()))
             if isinstance(node, ast.FunctionDef)
             and any(d in ast.unparse(node.decorator_list[0]) for d in ("ti.func", "ti.kernel")
                     if node.decorator_list)
             and len(lines := _discards(node)) > 1}
    assert not twice, twice


def test_every_term_feature_is_registered():
    """``features.FEATURES`` holds each term's feature (the same object), in the terms'
    order, then the strain limit and tearing: the model builds, refreshes and saves a
    feature only through that list."""
    from tcloth.features import FEATURES
    from tcloth.terms import TERMS
    of_terms = [t.feature for t in TERMS if t.feature is not None]
    assert list(FEATURES[:len(of_terms)]) == of_terms
    assert [f.name for f in FEATURES[len(of_terms):]] == ["strain_limit", "tearing"]


def test_the_model_keeps_each_feature_on_its_own_object(f32):
    """Every feature's build is one object, ``model.<feature name>``, of the class the
    Model's docstring names; the model has no loose ``<feature>_*`` attributes."""
    import tcloth
    from tcloth.features import FEATURES
    from tcloth.model.model import Model
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(4, 4), size=(0.3, 0.3), structural=(100.0, 0.0),
                    shear=(10.0, 0.0), flexion=None)
    tetrahedron = [[0.0, 2.0, 0.0], [0.1, 2.0, 0.0], [0.0, 2.1, 0.0], [0.0, 2.0, 0.1]]
    scene.add_mesh_cloth(tetrahedron, [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
                         structural=(100.0, 0.0), flexion=None)
    scene.set_bending(1e-4, cloths=[0])
    scene.set_membrane(stretch=50.0, shear=5.0, cloths=[0])
    scene.set_wind(velocity=(1.0, 0.0, 0.0))
    scene.add_attraction(1e-3, softening=0.1)
    scene.set_pressure(100.0, cloths=[1])
    scene.set_self_collision()
    scene.limit_strain()
    torn = tcloth.Scene()           # tearing refuses the features a tear does not cut yet
    torn.add_cloth(resolution=(4, 4))
    torn.set_tearing()
    model, torn_model = Model(scene), Model(torn)
    for feature in FEATURES:
        data = getattr(torn_model if feature.name == "tearing" else model, feature.name)
        assert not isinstance(data, (type(None), dict, tuple)), feature.name
        assert f"``features.{feature.name}.{type(data).__name__}``" in Model.__doc__ or \
            f"``contact.topology.{type(data).__name__}``" in Model.__doc__, feature.name
    prefixes = tuple(f"{f.name}_" for f in FEATURES) + ("limit_", "triangle")
    assert not [name for m in (model, torn_model) for name in vars(m)
                if name.startswith(prefixes)]


def test_tests_import_nothing_from_tools():
    """The tests import the references they share with the benchmarks from
    ``tcloth.testing`` and their own helpers from ``tests/support``; tools/ scripts are only
    run as a user runs them (a subprocess), which tests the tool itself."""
    tests = os.path.dirname(os.path.abspath(__file__))
    found = []
    for folder, _, files in os.walk(tests):
        for f in sorted(files):
            if not f.endswith(".py"):
                continue
            path = os.path.join(folder, f)
            for node in ast.walk(ast.parse(open(path).read())):
                if isinstance(node, ast.Call) and "tools" in ast.unparse(node.args) and \
                        ast.unparse(node.func).endswith(("sys.path.insert", "sys.path.append",
                                                         "spec_from_file_location")):
                    found.append(f"{os.path.relpath(path, tests)}:{node.lineno}")
    assert not found, found
