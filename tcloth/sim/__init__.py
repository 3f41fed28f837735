"""Simulation: the ``Simulator`` (``simulator.py``: steps, live setters, state access),
batches of substeps in one launch (``batch.py``), the energy budget and strain bound
that catch an unstable step (``budget.py``, ``instability.py``), diagnostics (energies,
momentum, strain: ``diagnostics.py``), strain limiting (``constraints.py``) and
checkpoints (``checkpoint.py``)."""
