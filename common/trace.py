"""The one HTTP header of the project's own: when the data behind a PTZ command was measured.

The PTZ service sends it with every command; real cameras ignore a header they do not know,
the simulated ones record it for the latency figures (mocap frame → command at the camera).
"""

TRACE_HEADER = "X-STB-Measured"
