"""The tracking camera's host: frames from a camera on this host onto the bus."""
