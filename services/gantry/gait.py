"""A walking robot's gait, measured from its track (pure, numpy): the frequency at which its
marker sways.

The last ``window_s`` of positions, less their trend (a parabola per axis over the window), are
projected onto sines over a grid of frequencies (``low_hz``…``high_hz``); the strongest
frequency is the gait's if its amplitude is at least ``min_amplitude_mm``, it stands out from
the rest of the spectrum (``prominence`` times the median power), lies inside the band (not at
its edge, where what is left of a curved path leaks in) and explains at least ``share`` of
what the trend leaves. Measured again every ``every_s``. A gait once found is confirmed by
its frequency alone: while it stands out there (``prominence`` times the median power, at
least ``min_amplitude_mm``) it is kept, however much a slide or a turn adds to the window
around it; it is kept through ``keep_s`` of windows that do not show it, and no other
frequency replaces it before then (a slide's low frequencies can pass the test above for a
window or two). Without one (a wheeled robot, a robot standing) ``omega_rad_s`` is 0.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np


@dataclass
class GaitMeter:
    window_s: float = 6.0
    every_s: float = 1.0
    low_hz: float = 0.4
    high_hz: float = 3.0
    step_hz: float = 0.05
    min_amplitude_mm: float = 2.0
    prominence: float = 8.0
    share: float = 0.5
    keep_s: float = 10.0
    omega_rad_s: float = 0.0
    amplitude_mm: float = 0.0
    _t: deque[float] = field(default_factory=deque)
    _z: deque[np.ndarray] = field(default_factory=deque)
    _measured_s: float = -np.inf
    _found_s: float = -np.inf

    def reset(self) -> None:
        self._t.clear()
        self._z.clear()
        self._measured_s = self._found_s = -np.inf
        self.omega_rad_s = self.amplitude_mm = 0.0

    def add(self, t_s: float, z: np.ndarray) -> None:
        self._t.append(t_s)
        self._z.append(z)
        while self._t[0] < t_s - self.window_s:
            self._t.popleft()
            self._z.popleft()
        if t_s - self._measured_s >= self.every_s and \
                self._t[-1] - self._t[0] >= 0.8 * self.window_s:
            self._measured_s = t_s
            omega, self.amplitude_mm = self._measure()
            lost = t_s - self._found_s > self.keep_s
            if omega > 0 and (omega == self.omega_rad_s or self.omega_rad_s == 0 or lost):
                self.omega_rad_s, self._found_s = omega, t_s
            elif lost:
                self.omega_rad_s = 0.0

    def _measure(self) -> tuple[float, float]:
        t = np.array(self._t) - self._t[-1]
        z = np.array(self._z)
        trend = np.vander(t, 3)
        coef, *_ = np.linalg.lstsq(trend, z, rcond=None)
        residual = z - trend @ coef  # (N, 2)
        freqs = np.arange(self.low_hz, self.high_hz + 1e-9, self.step_hz)
        phasors = np.exp(-2j * np.pi * np.outer(freqs, t))  # (F, N)
        amplitude = 2 * np.abs(phasors @ residual) / len(t)  # (F, 2)
        power = (amplitude ** 2).sum(axis=1)
        if self.omega_rad_s > 0:  # the gait known: is it still there, whatever else moved?
            near = np.abs(freqs - self.omega_rad_s / (2 * np.pi)) <= self.step_hz * 1.01
            kept = float(power[near].max())
            if self._stands_out(kept, power):
                return self.omega_rad_s, float(np.sqrt(kept))
        best = int(np.argmax(power))
        strongest = float(np.sqrt(power[best]))
        freq = float(freqs[best])
        if 0 < best < len(freqs) - 1:  # the peak between the grid's steps (a parabola)
            before, at, after = power[best - 1: best + 2]
            bend = before - 2 * at + after
            if bend < 0:  # to 0.01 Hz: the filter keeps its matrices per gait
                freq = round(freq + 0.5 * (before - after) / bend * self.step_hz, 2)
        explained = 0.5 * power[best] / max(float((residual ** 2).sum(axis=1).mean()), 1e-9)
        if not self._stands_out(float(power[best]), power) or best in (0, len(freqs) - 1) \
                or explained < self.share:
            return 0.0, strongest
        return 2 * np.pi * freq, strongest

    def _stands_out(self, peak_power: float, power: np.ndarray) -> bool:
        """A sine of this power is a sway: large enough, and well above the spectrum's median."""
        return np.sqrt(peak_power) >= self.min_amplitude_mm and \
            peak_power >= self.prominence * float(np.median(power))
