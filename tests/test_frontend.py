"""tcloth.runtime.frontend remembers Taichi's source positions and sources: the texts must be
Taichi's own, and a compile error must still point at its line."""
import inspect

import numpy as np
import pytest
import taichi as ti
from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext

import tcloth
from tcloth.runtime import frontend


def test_it_is_installed_on_this_taichi():
    assert frontend.install()
    assert hasattr(ASTTransformerContext.get_pos_info, "original")


def test_remembered_positions_are_taichis_own_texts(f32, monkeypatch):
    """Every position text asked for while a simulator with a collider compiles and
    steps (its kernels share ti.funcs, so the memo answers most), from the memo and from
    Taichi's function alike."""
    remembered = ASTTransformerContext.get_pos_info
    original = remembered.original
    asked, differ = [], []

    def both(self, node):
        text = remembered(self, node)
        asked.append(frontend.position_key(self, node))
        if text != original(self, node):
            differ.append((self.file, node.lineno, type(node).__name__))
        return text

    monkeypatch.setattr(ASTTransformerContext, "get_pos_info", both)
    scene = tcloth.Scene()
    scene.add_cloth(resolution=(4, 4), size=(0.3, 0.3), center=(0.0, 0.5, 0.0))
    scene.add_sphere((0.0, 0.3, 0.0), 0.1, friction=0.3)
    tcloth.Simulator(scene, integrator="symplectic_euler", dt=1e-3).step(2)
    assert differ == []
    assert len(asked) > 1000 and len(set(asked)) < len(asked) / 2     # the memo is used


@ti.func
def _reads_an_undefined_name(x):
    return x + undefined_here        # noqa: F821 (the error this test compiles)


def test_a_compile_error_still_names_its_line(f32):
    field = ti.field(ti.f32, shape=2)

    @ti.kernel
    def first():
        for i in field:
            field[i] = _reads_an_undefined_name(field[i])

    @ti.kernel
    def second():
        for i in field:
            field[i] = 2.0 * _reads_an_undefined_name(field[i])

    _, start = inspect.getsourcelines(_reads_an_undefined_name)
    line = start + 2
    for kernel in (first, second):
        with pytest.raises(ti.TaichiCompilationError) as error:
            kernel()
        message = str(error.value)
        assert f"line {line}, in _reads_an_undefined_name" in message
        assert "return x + undefined_here" in message and "^" in message
    assert np.all(field.to_numpy() == 0.0)
