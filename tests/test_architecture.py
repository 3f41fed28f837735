"""What docs/architecture.md promises about the code's shape: the imports of tcloth's
modules form no cycle (read from the source, function-level imports included), the model
imports no term, the scene no Taichi module of the physics, and no file is over 500
lines."""
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
    assert not {m for m in graph["tcloth.model"] if m.startswith("tcloth.terms")}
    below_scene = reaches(graph, "tcloth.scene")
    assert not {m for m in below_scene if m.startswith(("tcloth.terms", "tcloth.model",
                                                        "tcloth.integrators"))}


def test_no_file_is_over_500_lines():
    long = {path: n for path in modules().values()
            if (n := sum(1 for _ in open(path))) > 500}
    assert not long, long
