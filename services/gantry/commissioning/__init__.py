"""Commissioning the crane, one module group per command: ``stb gantry identify`` (the crane's
dynamics and the loop's delays: ``identify*.py``) and ``stb gantry commission`` (a crane's
first day — its frame, the tracking camera's lens and mount, then the dynamics:
``commission*.py``, with ``geometry_fit.py``'s arithmetic). docs/commissioning.md."""
