"""``python -m tcloth``: the tcloth command line."""
import sys

from .cli import main

sys.exit(main())
