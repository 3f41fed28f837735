"""Contact: the self-contact topology and exclusion rule (``topology.py``), closest points
(``proximity.py``), the proximity list's broad phase (``broad.py``) and the swept-box
search of a step (``swept.py``), both one candidate search (``search.py``) over the cell
hash's grids (``hashgrid.py``), the guard that keeps every step's motion
from crossing cloth or entering colliders (``guard.py``), and the stage that owns them, one
per simulator (``stage.py``; docs/contact.md)."""
