"""The API reference (docs/reference/, built by MkDocs with mkdocstrings: mkdocs.yml) covers
the public API: every public name has a ``:::`` block, the reference pages are in the nav,
and what the reference writes by hand (the collider builders' signatures, the feature
setters, the command line's options) matches the code. The build itself, with warnings as
errors, is `.ci/run`'s (``mkdocs build --strict``); these checks need neither MkDocs nor a
kernel."""
import glob
import inspect
import os
import re

import pytest

import tcloth
from tcloth.app import sweep
from tcloth.features import FEATURES
from tcloth.geometry.shapes import SHAPES, collider_builder

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REFERENCE = os.path.join(REPO, "docs", "reference")


def _read(path):
    with open(path, encoding="utf-8") as f:
        return f.read()


def _pages():
    return {os.path.basename(p): _read(p) for p in sorted(glob.glob(os.path.join(REFERENCE,
                                                                                "*.md")))}


def _documented():
    """The dotted names the reference documents: each ``::: path`` block's path, and the
    ``heading:`` a block gives where it documents an object under another name (the
    function ``tcloth.render``, whose path is taken by the package)."""
    names = set()
    for text in _pages().values():
        names.update(re.findall(r"^::: *([\w.]+)", text, re.M))
        names.update(re.findall(r"^ +heading: *([\w.]+) *$", text, re.M))
    return names


@pytest.mark.parametrize("module, prefix", [(tcloth, "tcloth"), (tcloth.grad, "tcloth.grad"),
                                            (sweep, "tcloth.app.sweep")],
                         ids=["tcloth", "grad", "sweep"])
def test_every_public_name_has_a_reference_entry(module, prefix):
    documented = _documented()
    missing = [name for name in module.__all__ if f"{prefix}.{name}" not in documented]
    assert not missing, (f"{prefix}.__all__ names without a '::: {prefix}.NAME' block in "
                         f"docs/reference/: {missing}")


def test_reference_pages_are_in_the_nav():
    nav = _read(os.path.join(REPO, "mkdocs.yml"))
    missing = [page for page in _pages() if f"reference/{page}" not in nav]
    assert not missing, f"docs/reference pages missing from mkdocs.yml's nav: {missing}"


def test_collider_builders_signatures_match():
    """The builders are made at import (not in Scene's source, so mkdocstrings cannot
    read them): the reference writes each one's signature, which must be the code's."""
    text = " ".join(_pages()["scene.md"].split())
    for shape in SHAPES:
        if shape.meshed:
            continue
        parameters = list(inspect.signature(collider_builder(shape)).parameters.values())[1:]
        call = f"scene.add_{shape.name}{inspect.Signature(parameters)}"
        assert call in text, f"docs/reference/scene.md should show {call}"


def test_feature_setters_are_documented():
    text = _pages()["scene.md"]
    for feature in FEATURES:
        cls = type(feature)
        block = f"::: {cls.__module__}.{cls.__name__}.set\n    options:\n      " \
                f"heading: Scene.{feature.method}\n"
        assert block in text, f"docs/reference/scene.md should document Scene.{feature.method}"


def test_command_line_options_are_documented():
    text = _pages()["cli.md"]
    options = set(re.findall(r"add_argument\(\s*\"(--[\w-]+)\"",
                             _read(os.path.join(REPO, "tcloth", "app", "cli.py"))))
    assert options
    missing = sorted(o for o in options if f"`{o}" not in text)
    assert not missing, f"command-line options missing from docs/reference/cli.md: {missing}"
