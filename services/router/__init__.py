"""Embedded Zenoh router: the bus's hub for local runs (the lab may use eclipse/zenoh instead)."""
