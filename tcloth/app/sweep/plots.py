"""A sweep's pictures (matplotlib; skipped with one line where it is not installed):

- ``stability_map.png`` where dt and a numeric build parameter (a stiffness, or the first
  number of a [k_s, k_d] pair) are varied: stable (green o) and unstable (red x) cases
  over (parameter, dt), one panel per combination of the other varied keys, with symplectic
  Euler's limit 2 / omega_max of each scene (``tcloth.stability``).
- ``work_precision.png`` where a reference is given: error against run time and against
  dt, one line per combination of the varied keys other than dt, with the convergence
  order fitted over the points below 10 % of the scene's size in the legend (or why
  there is none).
Legends sit below the axes; ticks on short log ranges are the swept values themselves.
"""
import json
import math
import os
import sys

import numpy as np

from ..script import load_script
from ...scene.stability import explicit_dt_limit
from .spec import SETTINGS


def _numeric(value):
    """The number a varied value is drawn at (a pair's first number), or None."""
    if isinstance(value, list) and value:
        value = value[0]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value)


def _plain_keys(spec):
    """Varied keys that take plain values (not tables of several settings)."""
    return [k for k in spec.vary if k not in spec.grouped]


def _panels(rows, keys):
    """(title, rows) per combination of the values of ``keys`` (one panel without keys)."""
    combos = {}
    for row in rows:
        combos.setdefault(tuple(row[k] for k in keys), []).append(row)
    return [(", ".join(f"{k}={v}" for k, v in zip(keys, combo)) or "all cases", members)
            for combo, members in combos.items()]


def order(points, size):
    """Least-squares slope of log error against log dt over stable points with an error
    below 10 % of ``size`` (nan with fewer than two)."""
    pts = [(dt, err) for dt, err in points if 0 < err < 0.1 * size]
    if len(pts) < 2:
        return float("nan")
    dt, err = np.log(np.array(pts)).T
    return float(np.polyfit(dt, err, 1)[0])


def plot_all(spec, rows, out):
    """Draw what the sweep supports into ``out``; returns the paths written."""
    try:
        import matplotlib
    except ImportError:
        print("# sweep plots skipped: matplotlib is not installed "
              "(pip install 'tcloth[sweep]')", file=sys.stderr)
        return []
    matplotlib.use("Agg")
    paths = []
    x_key = next((k for k in _plain_keys(spec) if k not in SETTINGS
                  and all(_numeric(shown) is not None for _, shown in spec.vary[k])), None)
    if "dt" in spec.vary and x_key is not None:
        paths.append(stability_map(spec, rows, x_key, os.path.join(out, "stability_map.png")))
    if spec.reference is not None and any(_finite(r["error"]) for r in rows):
        paths.append(work_precision(spec, rows, os.path.join(out, "work_precision.png")))
    return paths


def _finite(value):
    return isinstance(value, (int, float)) and math.isfinite(value)


def _shown(value):
    return json.loads(value) if isinstance(value, str) and value[:1] in "[{" else value


def _log_ticks(axis, values):
    """Ticks at the sweep's own values where there are few (log axes label minor ticks
    over a short range, and "3x10^3 4x10^3" run into each other), decades otherwise; no
    minor labels."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter
    values = sorted({v for v in values if v is not None and v > 0})
    if 0 < len(values) <= MAX_VALUE_TICKS:
        axis.set_major_locator(FixedLocator(values))
        axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(NullFormatter())


MAX_VALUE_TICKS = 6


def stability_map(spec, rows, x_key, path):
    import matplotlib.pyplot as plt
    others = [k for k in spec.vary if k not in ("dt", x_key)]
    panels = _panels(rows, others)
    cols = min(3, len(panels))
    fig, axes = plt.subplots((len(panels) + cols - 1) // cols, cols, squeeze=False,
                             figsize=(4.4 * cols, 3.8 * ((len(panels) + cols - 1) // cols)),
                             sharex=True, sharey=True)
    module, _ = load_script(spec.scene)
    cases = {c["id"]: c for c in spec.cases()}
    limits = {}
    for ax, (title, members) in zip(axes.flat, panels):
        for r in members:
            x = _numeric(_shown(r[x_key]))
            ax.scatter(x, r["dt"], c="tab:green" if r["stable"] else "tab:red",
                       marker="o" if r["stable"] else "x", s=30)
        line = []
        for r in members:
            build = cases[r["id"]]["build"]
            key = json.dumps(build, sort_keys=True)
            if key not in limits:
                limits[key] = explicit_dt_limit(module.build(**build))
            line.append((_numeric(_shown(r[x_key])), limits[key]))
        line = sorted(set(line))
        ax.plot(*zip(*line), "k--", lw=1, label="2 / omega_max")
        ax.set(xscale="log", yscale="log", title=title)
        ax.margins(0.08)                   # markers at the extremes stay whole
        ax.title.set_fontsize(9)
    for ax in axes.flat[len(panels):]:
        ax.set_visible(False)
    for ax in axes.flat[:len(panels)]:
        _log_ticks(ax.xaxis, [_numeric(_shown(r[x_key])) for r in rows])
        _log_ticks(ax.yaxis, [r["dt"] for r in rows])
    for ax in axes[-1]:
        ax.set_xlabel(x_key)
    for ax in axes[:, 0]:
        ax.set_ylabel("dt (s)")
    fig.suptitle(f"{os.path.basename(spec.scene)}: stable (green o) / unstable (red x)")
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    # below the panels, where it hides no marker
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="lower center", fontsize=8,
               frameon=False)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def work_precision(spec, rows, path):
    import matplotlib.pyplot as plt
    size = scene_size(spec)
    panels = _panels(rows, [k for k in spec.vary if k != "dt"])
    fig, (ax_t, ax_dt) = plt.subplots(1, 2, figsize=(12, 4.5 + 0.25 * ((len(panels) + 1) // 2)))
    for title, members in panels:
        pts = sorted((r["dt"], r["error"], r["ms_per_step"] * r["steps"] / 1e3)
                     for r in members if r["stable"] and _finite(r["error"])
                     and r["error"] > 0)
        if not pts:
            continue
        dt, err, wall = np.array(pts).T
        fitted = order(list(zip(dt, err)), size)
        label = (f"{title} (order {fitted:.2f})" if math.isfinite(fitted) else
                 f"{title} (no order: {len(pts)} stable point{'s' * (len(pts) != 1)} "
                 f"below 10 % of the size)" if len(pts) > 1 else
                 f"{title} (one stable point)")
        ax_t.plot(wall, err, "o-", label=label)
        ax_dt.plot(dt, err, "o-", label=label)
    ax_t.set(xscale="log", yscale="log", xlabel="run time (s)", ylabel="RMS error (m)",
             title="error against run time")
    ax_dt.set(xscale="log", yscale="log", xlabel="dt (s)", ylabel="RMS error (m)",
              title="error against dt (missing points: unstable)")
    _log_ticks(ax_dt.xaxis, [r["dt"] for r in rows])
    for ax in (ax_t, ax_dt):
        ax.margins(0.06)
    handles, labels = ax_t.get_legend_handles_labels()
    legend_rows = (len(labels) + 1) // 2
    fig.suptitle(f"{os.path.basename(spec.scene)}: work-precision against "
                 f"{spec.reference['integrator']} at dt = {spec.reference['dt']:g}")
    fig.tight_layout(rect=(0, 0.045 * legend_rows + 0.02, 1, 1))
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=8, frameon=False)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def scene_size(spec):
    """Bounding-box diagonal of the first case's scene at rest, m."""
    module, _ = load_script(spec.scene)
    x = module.build(**spec.cases()[0]["build"]).positions
    return float(np.linalg.norm(x.max(axis=0) - x.min(axis=0)))
