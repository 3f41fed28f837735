"""Taichi's Python frontend, made cheaper to run again over the same source.

Taichi 1.7 builds each kernel from its Python source for every instance it compiles (a
``ti.data_oriented`` object's kernels compile once per object, and a ``ti.func`` is
inlined anew at each call), and on every AST node it formats the node's source position
for its error messages (a few lines wrapped by ``textwrap``), whether or not an error
comes. Two lookups repeat unchanged across those builds and are remembered here:

  - the position text of a node (``ASTTransformerContext.get_pos_info``): a function of
    the function's file and first line, its indentation, the node's type and its line
    and column span (and, for a block, its body's first line), which is the key;
  - the source of a kernel or ``ti.func`` (``getsourcelines``, ``getsourcefile``), per
    function object.

The texts are Taichi's own, character for character (``tests/test_frontend.py``). What it
saves: 3 % (symplectic Euler) to 23 % (backward Euler) of building a simulator, a fifth of
tests/test_live.py's time (docs/benchmarks.md, "Taichi's frontend"). ``install`` is a
no-op on another Taichi than 1.7 or where the names moved.

It also counts the kernels Taichi compiles (``compilations``: each new instance of a
kernel, a template argument or a field it has not seen before), so that a test can assert
that a simulator compiles nothing after its first frame.
"""
import functools

import taichi as ti

_installed = False
_compiled = [0]


def compilations():
    """How many kernel instances Taichi has compiled in this process (None where the
    count could not be installed: another Taichi than 1.7)."""
    return _compiled[0] if _installed else None


def position_key(context, node):
    """What ``get_pos_info(node)`` depends on in ``context`` (an ASTTransformerContext)."""
    body = getattr(node, "body", None)
    first = body[0].lineno if isinstance(body, list) and body else None
    return (context.file, context.lineno_offset, context.func.func.__name__, context.indent,
            type(node), node.lineno, node.end_lineno, node.col_offset, node.end_col_offset,
            first)


def install():
    """Remember positions and sources (see the module); once per process. Returns whether
    it is installed."""
    global _installed
    if _installed:
        return True
    if ti.__version__[:2] != (1, 7):
        return False
    try:
        from taichi.lang import kernel_impl
        from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext
        original = ASTTransformerContext.get_pos_info
        sources = kernel_impl.getsourcelines, kernel_impl.getsourcefile
    except (ImportError, AttributeError):
        return False
    texts = {}

    def get_pos_info(self, node):
        key = position_key(self, node)
        text = texts.get(key)
        if text is None:
            text = texts[key] = original(self, node)
        return text

    get_pos_info.original = original
    ASTTransformerContext.get_pos_info = get_pos_info
    materialize = kernel_impl.Kernel.materialize

    def counted(self, key=None, args=None, arg_features=None):
        if (key if key is not None else (self.func, 0, self.autodiff_mode)) \
                not in self.compiled_kernels:
            _compiled[0] += 1
        return materialize(self, key, args, arg_features)

    kernel_impl.Kernel.materialize = counted
    kernel_impl.getsourcelines, kernel_impl.getsourcefile = (
        functools.lru_cache(maxsize=None)(f) for f in sources)
    _installed = True
    return True
