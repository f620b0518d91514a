"""The paper's experiments on a simulated clock: the gantry's own controller against the sim's
devices (``stb experiment``). A harness, not a service: it is the one place that puts the
gantry and the sim together in one process."""
