"""The sim's crane controller and tracking camera as the gantry's drivers see them, on a
simulated clock: the same register encoding as over Modbus/TCP, frames that arrive as over
the bus (after their exposure and a delay), no sockets and no waiting."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import overload

import numpy as np

from common.crane_frame import CRANE_COUNTS_IN_THE_WORLD, CraneFrame
from common.crane_registers import RegisterMap
from services.gantry.control import Fix
from services.gantry.crane import RegisterCrane
from services.gantry.frames import Frame
from services.sim.crane import CraneModel
from services.sim.crane_server import input_registers, write_holding
from services.sim.lab import Lab


class SimClock:
    """The experiment's time, set by its loop."""

    def __init__(self, now_s: float = 0.0) -> None:
        self.now_s = now_s

    def __call__(self) -> float:
        return self.now_s


class ModelCrane(RegisterCrane):
    """The ``Crane`` Protocol over the sim's crane model, through the register map and the
    crane's frame as the gantry's settings give it."""

    def __init__(self, model: CraneModel, clock: Callable[[], float], registers: RegisterMap,
                 frame: CraneFrame = CRANE_COUNTS_IN_THE_WORLD) -> None:
        super().__init__(registers, frame)
        self.model, self.clock = model, clock
        self._holding = [0] * registers.holding_count
        self._block: tuple[tuple, list[int]] | None = None  # the last state and its registers

    def _read_input(self) -> list[int]:
        model = self.model
        model.advance_to(self.clock())
        state = (model.report(), model.status(), model.faults, model.heartbeat,
                 model.setpoints_taken)
        if self._block is None or self._block[0] != state:
            self._block = state, input_registers(model, self.registers)
        return self._block[1]

    def _read_holding(self, start: int, count: int) -> list[int]:
        return self._holding[start:start + count]

    def _write(self, address: int, values: list[int]) -> None:
        self._holding[address:address + len(values)] = values
        write_holding(self.model, self.clock(), range(address, address + len(values)),
                      self._holding, self.registers)


class SimFrames:
    """The ``FrameSource`` Protocol: the sim's tracking camera, the newest frame that has
    arrived by now, rendered when it is taken."""

    def __init__(self, lab: Lab, clock: SimClock, rng: np.random.Generator) -> None:
        self.lab, self.clock, self.rng = lab, clock, rng
        self._taken = -1

    def take(self) -> Frame | None:
        recent = self.take_recent(1)
        return recent[0] if recent else None

    def take_recent(self, keep: int = 8) -> Sequence[Frame]:
        """The frames that arrived since the last take, newest first (at most ``keep``, as
        the bus's ``FrameInbox`` keeps), each rendered when it is first looked at (the
        paper's algorithms look at the newest only, unless it does not show the robot)."""
        number, _ = self.lab.newest_capture(self.clock())
        first = max(self._taken + 1, number - keep + 1, 0)
        if number < first:
            return []
        self._taken = number
        self.lab.crane.advance_to(self.clock())
        rate = self.lab.settings.tracking_camera.rate_hz
        return _Rendered([n / rate for n in range(number, first - 1, -1)],
                         lambda t: self.lab.tracking_frame(t, self.rng))


class _Rendered(Sequence[Frame]):
    """Frames (capture time, picture) whose pictures are drawn when first asked for."""

    def __init__(self, times: list[float], render: Callable[[float], np.ndarray],
                 drawn: dict[float, np.ndarray] | None = None) -> None:
        self.times, self.render = times, render
        self._drawn = {} if drawn is None else drawn

    def __len__(self) -> int:
        return len(self.times)

    @overload
    def __getitem__(self, index: int) -> Frame: ...

    @overload
    def __getitem__(self, index: slice) -> Sequence[Frame]: ...

    def __getitem__(self, index: int | slice) -> Frame | Sequence[Frame]:
        if isinstance(index, slice):
            return _Rendered(self.times[index], self.render, self._drawn)
        t = self.times[index]
        if t not in self._drawn:
            self._drawn[t] = self.render(t)
        return t, self._drawn[t]


class SimCraneMarker:
    """The motion capture's marker on the crane's carriage as the gantry's loop asks for it:
    the newest motion-capture frame by now (``[sim.mocap] rate_hz``), with its noise and its
    dropouts (the frame's marker lost: the last one seen stays)."""

    def __init__(self, lab: Lab, clock: SimClock, rng: np.random.Generator) -> None:
        self.lab, self.clock, self.rng = lab, clock, rng
        self._number = -1
        self._fix: Fix | None = None

    def __call__(self) -> Fix | None:
        mocap = self.lab.settings.mocap
        number = math.floor(self.clock() * mocap.rate_hz + 1e-9)
        if number != self._number:
            self._number = number
            if self.rng.random() >= mocap.dropout:
                t = number / mocap.rate_hz
                xy = self.lab.crane_marker(t)[:2] + self.rng.normal(0.0, mocap.noise_mm, 2)
                self._fix = Fix(t, xy)
        return self._fix
