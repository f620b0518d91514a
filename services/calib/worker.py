"""A solve in a short-lived worker process: scipy, cma and matplotlib load there and leave with
it, so the calib service holds only what it needs between calibrations (114 MB instead of
190 MB once the demo had solved: docs/benchmarks.md, "Memory").

The worker is a fresh interpreter (``python -m services.calib.worker``: nothing of the service's
threads or bus session is copied into it, and no helper process stays behind) that reads the
call from its standard input and writes the result, or the error it raised, to its standard
output, both pickled; its log goes to the service's standard error.
"""

from __future__ import annotations

import pickle
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, ParamSpec, TypeVar

from common.passpoints import CalibrationError, Passpoints

if TYPE_CHECKING:
    from services.calib.options import Options
    from services.calib.solve import Solution
    from services.calib.zoom_fit import ZoomFit

P = ParamSpec("P")
R = TypeVar("R")


def in_worker(call: Callable[P, R], *args: P.args, **kwargs: P.kwargs) -> R:
    """``call(*args, **kwargs)`` in a new process; its result, or its exception, here. A worker
    that ends without an answer (killed, out of memory) is a CalibrationError that says so."""
    done = subprocess.run([sys.executable, "-m", "services.calib.worker"],
                          input=pickle.dumps((call, args, kwargs)), stdout=subprocess.PIPE,
                          check=False)
    try:
        ok, value = pickle.loads(done.stdout)
    except (pickle.UnpicklingError, EOFError, ValueError) as err:
        raise CalibrationError(f"the solving process ended without a result (exit code "
                               f"{done.returncode})") from err
    if ok:
        return value
    raise value


def _serve() -> int:
    """The worker's side: one call from standard input, its outcome to standard output. The
    solver warms up first (while the call is on its way)."""
    from services.calib.solve import warm_up

    warm_up()
    call, args, kwargs = pickle.loads(sys.stdin.buffer.read())
    out, sys.stdout = sys.stdout.buffer, sys.stderr  # a print in the solve is a log line
    outcome: tuple[bool, Any]
    try:
        outcome = (True, call(*args, **kwargs))
    except Exception as err:  # noqa: BLE001 - every error goes back to the caller
        outcome = (False, err)
    try:
        answer = pickle.dumps(outcome)
    except Exception as err:  # noqa: BLE001 - what does not pickle goes back as its text
        failed = err if outcome[0] else outcome[1]
        answer = pickle.dumps((False, CalibrationError(f"{type(failed).__name__}: {failed}")))
    out.write(answer)
    out.flush()
    return 0


def solve_one_zoom(points: Passpoints, options: Options) -> Solution:
    """``solve.solve``, importable by name in the worker."""
    from services.calib.solve import solve

    return solve(points, options)


def solve_zooms_and_plot(by_zoom: dict[int, Passpoints], options: Options, plot: Path
                         ) -> tuple[ZoomFit, Solution, str | None]:
    """``zoom_fit.solve_zooms``, and the lens's picture written to ``plot``; the third item
    says why no picture was drawn (None: drawn)."""
    from services.calib.plot import write_lens_plot
    from services.calib.zoom_fit import solve_zooms

    fit, first = solve_zooms(by_zoom, options)
    try:
        write_lens_plot(fit, plot)
    except (OSError, ValueError) as err:  # a picture that cannot be drawn is only missed
        return fit, first, str(err)
    return fit, first, None


if __name__ == "__main__":
    sys.exit(_serve())
