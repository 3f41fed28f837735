"""CSV output shared by the benchmark tools (run as ``python tools/<tool>.py``, which puts
this folder on the import path)."""
import csv
import os


def write_csv(path, rows):
    """Rows (dicts) to ``path``; the columns are every key in the order first seen."""
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    fields = list(dict.fromkeys(key for row in rows for key in row))
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
    print(f"# wrote {path}")
