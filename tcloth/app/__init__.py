"""The front ends: the command line (``cli.py``), scene scripts (``script.py``) and
parameter sweeps (``sweep/``)."""
