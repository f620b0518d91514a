"""The AXIS 215 PTZ as its data sheet describes it (the paper's Table 1): the camera the lab
had, and what a camera that says nothing of itself is taken to be."""

from __future__ import annotations

AXIS_215_FOCAL_MM = (3.8, 46.0)  # the zoom lens's range
AXIS_215_ZOOM_STEPS = (1, 9999)  # VAPIX's zoom steps over that range
AXIS_215_CHIP_MM = (3.6, 2.7)  # a 1/4-inch 4:3 chip
AXIS_215_PICTURE_PX = (704, 576)  # its full picture (PAL D1: non-square pixels of that chip)
AXIS_215_PX_PER_MM = AXIS_215_PICTURE_PX[0] / AXIS_215_CHIP_MM[0]  # a focal length, mm → px
