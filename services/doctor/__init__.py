"""``stb doctor``: everything a lab's first run needs, checked against the lab file."""
