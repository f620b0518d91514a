"""``stb crater``: the crater's height map from a laser scan (paper §3.1)."""
