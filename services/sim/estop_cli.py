"""``stb sim estop [--release]``: press (or release) the simulated crane's e-stop.

The sim's crane controller has a safety circuit like a real one: pressing the e-stop opens it,
the crane brakes to a stop, disables itself and latches a safety fault; the gantry goes to
``stopped`` and says why. Releasing closes the circuit; the fault stays until an operator's
``stb gantry reset``. The button is a holding register of the sim's own
(``[sim.crane] estop_register``, 100), written over Modbus/TCP like any other.
Exit status: 0 done, 2 bad arguments, 3 the sim's crane controller does not answer.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from services.args import base_parser

if TYPE_CHECKING:  # imported once the flags are parsed: --help answers at once
    from services.sim.settings import SimSettings

EXIT_UNREACHABLE = 3


def main(argv: Sequence[str]) -> int:
    parser = base_parser("stb sim estop", __doc__ or "")
    parser.add_argument("--release", action="store_true", help="release it (close the circuit)")
    args = parser.parse_args(argv)
    from services.entry import tool_main, tool_settings
    from services.sim.settings import SimSettings

    return tool_main("sim estop", lambda: _press(args.release, tool_settings(SimSettings, args)))


def _press(release: bool, settings: SimSettings) -> int:
    from pymodbus.client import ModbusTcpClient
    from pymodbus.exceptions import ModbusException

    from services.entry import ToolError

    crane = settings.crane
    client = ModbusTcpClient(crane.host, port=crane.port, timeout=2, retries=0)
    try:
        if not client.connect():
            raise ModbusException(f"no connection to {crane.host}:{crane.port}")
        reply = client.write_register(crane.estop_register, 0 if release else 1,
                                      device_id=crane.registers.unit_id)
        if reply.isError():
            raise ModbusException(str(reply))
    except (ModbusException, OSError) as err:
        raise ToolError(f"the sim's crane controller does not take it: {err}",
                        EXIT_UNREACHABLE) from err
    finally:
        client.close()
    print("e-stop released: the safety circuit is closed (the fault stays until a reset)"
          if release else "e-stop pressed: the safety circuit is open")
    return 0
