"""``stb monitor``: watch the bus from any host (alive services, every key's latest value)."""
