"""PTZ service: points an AXIS camera at the tracked robot (paper §2.3)."""
