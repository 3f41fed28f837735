"""Helpers that only the tests use, shared between test modules (``from support.kernels
import ...``: pytest puts tests/ on the import path, the folder of the rootdir's conftest).
The references that the tests share with the benchmarks are ``tcloth.testing``'s."""
