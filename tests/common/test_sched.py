"""The short CPU slice: granted to every thread, inherited by later ones, bounded, optional."""

from __future__ import annotations

import subprocess
import sys

import pytest

from common.sched import request_slice
from common.settings import ConfigError, ServiceSettings, load_settings
from services.gantry.settings import GantrySettings
from services.ptz.settings import PtzSettings
from services.router.settings import RouterSettings
from services.tracker.settings import TrackerSettings

# In a child process: the slice stays with the process that asked for it.
_CHILD = """
import threading
from common.sched import request_slice, slice_ms_of
before = slice_ms_of()
earlier = threading.Event(); seen = {}
def wait_then_look():
    earlier.wait(); seen["earlier"] = slice_ms_of()
thread = threading.Thread(target=wait_then_look); thread.start()
refused = request_slice(0.1)
earlier.set(); thread.join()
later = threading.Thread(target=lambda: seen.update(later=slice_ms_of()))
later.start(); later.join()
print(before, refused, slice_ms_of(), seen["earlier"], seen["later"])
"""


def test_every_thread_gets_the_slice_also_those_started_before_and_after() -> None:
    out = subprocess.run([sys.executable, "-c", _CHILD], capture_output=True, text=True,
                         check=True).stdout.split()
    before, refused, main, earlier, later = out
    assert float(before) > 0.1, "the kernel's default slice before asking"
    assert refused == "None"
    assert float(main) == float(earlier) == float(later) == pytest.approx(0.1)


def test_a_slice_outside_the_kernels_bounds_is_refused_before_asking() -> None:
    with pytest.raises(ValueError, match="outside"):
        request_slice(0.05)


def test_the_chain_asks_for_the_short_slice_by_default_others_do_not() -> None:
    for cls in (RouterSettings, TrackerSettings, PtzSettings):
        assert cls().sched_slice_ms == 0.1, cls.__name__
    assert GantrySettings().sched_slice_ms is None
    assert ServiceSettings().sched_slice_ms is None


def test_a_bad_slice_stops_start_up_naming_the_field(tmp_path) -> None:  # noqa: ANN001
    lab = tmp_path / "lab.toml"
    lab.write_text("[tracker]\nsched_slice_ms = 0.01\n")
    with pytest.raises(ConfigError, match="tracker.sched_slice_ms"):
        load_settings(TrackerSettings, lab)
