"""How ``make test-system`` shares its tests between two workers (``--dist loadgroup``), and
what each worker did, printed at the end: when a run is long, whether a worker waited.

* Each package of ``SHARED_LABS`` runs on one worker, so that its lab runs once and not
  beside itself; every other test is a unit of its own. xdist's own grouping (the
  ``xdist_group`` mark) does not work under pytest 9 (it renames ``item._nodeid``, which
  pytest 9 no longer reads): the operator package ran on both workers, two labs and two
  browsers at once on two cores, and a CI run failed on it.
* The units go out in collection order after the shared package (xdist puts the units with
  most tests first), but ``LONG`` come right after the calibration tests instead of last in
  the run; and a worker holds two tests at most (the one it runs and the next: an xdist
  worker starts a test once it knows the next), not xdist's three. At the run's end the fault
  campaign and the crane's first day (about three minutes each) kept one worker busy while
  the other had nothing left (a CI run on 2026-12-07: 885 s for durations that add up to
  about 1,450 s); and with them queued earlier but three held, one worker took the
  calibration tests, the zoom collection, the campaign and the first day while the other ran
  the operator package and then the rest.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

import pytest

SHARED_LABS = ("tests/operator/",)
"""Packages whose tests share one lab (a package-scoped fixture such as ``live_lab``)."""
LONG = ("tests/reliability/test_fault_campaign.py", "tests/gantry/test_commission.py")
"""Units of minutes, queued right after ``AFTER``'s tests rather than at the run's end."""
AFTER = "tests/calib/"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getvalue("dist") != "loadgroup":
        return

    def rank(index_item: tuple[int, pytest.Item]) -> tuple[int, int]:
        index, item = index_item
        if item.nodeid.startswith(AFTER):
            return 0, index
        return (1 if item.nodeid.startswith(LONG) else 2), index
    items[:] = [item for _, item in sorted(enumerate(items), key=rank)]


def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class SharedLabScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return next((p for p in SHARED_LABS if nodeid.startswith(p)), nodeid)

        def _reschedule(self, node: Any) -> None:
            """A worker is given its next unit once it holds one test at most: xdist's
            three held a long test back on a busy worker while the other had run out."""
            if node.shutting_down:
                return
            if not self.workqueue:
                node.shutdown()
            elif self._pending_of(self.assigned_work[node]) <= 1:
                self._assign_work_unit(node)

    return SharedLabScheduling(config, log)


_timeline: dict[str, list[tuple[float, float, str]]] = defaultdict(list)


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    worker = getattr(getattr(report, "node", None), "gateway", None)
    if worker is not None:  # on the controller of an xdist run: which worker ran it, when
        _timeline[worker.id].append((report.start, report.stop, report.nodeid))


def pytest_terminal_summary(terminalreporter: Any) -> None:
    if not _timeline:
        return
    began = min(start for runs in _timeline.values() for start, _, _ in runs)
    terminalreporter.section("what each worker did")
    for worker, runs in sorted(_timeline.items()):
        busy = sum(stop - start for start, stop, _ in runs)
        last = max(runs, key=lambda run: run[1])
        terminalreporter.write_line(
            f"{worker}: busy {busy:.0f} s, done {last[1] - began:.0f} s after the first test "
            f"began; its last: {last[2]}")
