"""``python -m tcloth``: the tcloth command line."""
import sys

from .app.cli import main

sys.exit(main())
