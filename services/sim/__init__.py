"""The simulated Space Testbed: the lab's devices on their real protocols."""
