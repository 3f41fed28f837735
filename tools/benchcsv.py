"""CSV output and the solver specs shared by the benchmark tools (run as ``python
tools/<tool>.py``, which puts this folder on the import path)."""
import ast
import csv
import os


def integrator_spec(spec):
    """(integrator, its options, a label) of NAME or NAME:OPTION=VALUE (VALUE a Python
    literal), e.g. ``vbd:bounds=True``."""
    integrator, _, option = spec.partition(":")
    options = {}
    if option:
        key, value = option.split("=")
        options[key] = ast.literal_eval(value)
    return integrator, options, integrator + (f".{option}" if option else "")


def write_csv(path, rows):
    """Rows (dicts) to ``path``; the columns are every key in the order first seen."""
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    fields = list(dict.fromkeys(key for row in rows for key in row))
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
    print(f"# wrote {path}")
