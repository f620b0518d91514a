"""The doctor's rows without a lab (pure): the table and the exit status, the crane's
plausibility through a register map, the clocks' verdict, the access control against what
the lab file renders."""

from __future__ import annotations

from pathlib import Path

from common.crane_frame import CraneConnection
from common.crane_registers import SAFETY_OK
from services.deploy.render import cameras_of, router_config
from services.doctor.devices import _plausible
from services.doctor.lab import access_control, clocks, disk
from services.doctor.table import exit_status, failed, passed, render, skipped

WORKSPACE = (-3000.0, 3000.0, -3000.0, 3000.0)


def _block(registers: CraneConnection, x: float, y: float, status: int = SAFETY_OK
           ) -> list[int]:
    block = [0] * registers.input_count
    for name, value in (("actual_x", x), ("actual_y", y)):
        at = getattr(registers, name) - registers.input_start
        block[at:at + registers.width(name)] = registers.encode(name, value)
    block[registers.status - registers.input_start] = status
    return block


def test_the_table_says_each_verdict_and_the_fix_and_fails_only_on_a_failure() -> None:
    rows = [passed("a", "fine"), skipped("b", "not here"), failed("c", "broken", "mend it")]
    text = render(rows)
    assert "c" in text and "FAIL  broken" in text and "fix: mend it" in text
    assert "1 of 3 checks failed" in text
    assert exit_status(rows) == 1 and exit_status(rows[:2]) == 0


def test_a_crane_read_through_the_right_map_is_plausible_through_a_wrong_one_not() -> None:
    right = CraneConnection()
    block = _block(right, 1200.0, -800.0)
    assert _plausible("crane", "here", block, right, WORKSPACE).verdict == "pass"
    swapped = CraneConnection(word_order="low_first")
    row = _plausible("crane", "here", block, swapped, WORKSPACE)
    assert row.verdict == "fail" and "outside the workspace" in row.found
    assert "[gantry.crane.registers]" in row.fix
    odd = _plausible("crane", "here", _block(right, 0.0, 0.0, status=0x8000), right, WORKSPACE)
    assert odd.verdict == "fail" and "bits the map does not define" in odd.found


def test_a_host_off_by_more_than_the_tolerance_is_named() -> None:
    assert clocks({"gantry-pc": 0.004, "camera-pc": -0.03}, 0.1).verdict == "pass"
    row = clocks({"gantry-pc": 0.004, "camera-pc": -0.5}, 0.1)
    assert row.verdict == "fail" and "camera-pc" in row.fix and "gantry-pc" not in row.fix
    assert clocks({}, 0.1).verdict == "fail"


def test_the_access_control_is_what_the_lab_file_renders(tmp_path: Path) -> None:
    assert access_control(None, None).verdict == "skip"
    config, lab = tmp_path / "router.json5", tmp_path / "lab.toml"
    rendered = router_config(cameras_of(["ptz1", "ptz2"]))
    config.write_text(rendered)
    assert access_control(config, None).verdict == "pass"  # the default cameras: ptz1, ptz2
    lab.write_text('[ptz.cameras.ptz3]\nurl = "http://10.0.0.3"\n')
    assert access_control(config, lab).verdict == "fail", "ptz3 has no rule"
    config.write_text(rendered.replace('"stb/recording/*"', ""))
    row = access_control(config, None)
    assert row.verdict == "fail" and "missing" in row.found and "stb deploy render" in row.fix
    assert access_control(tmp_path / "none.json5", None).verdict == "fail"


def test_the_disk_row_looks_at_the_folder_or_where_it_will_be(tmp_path: Path) -> None:
    assert disk(tmp_path / "not" / "yet", 0.0).verdict == "pass"
    assert disk(tmp_path, 1e9).verdict == "fail"  # a billion gigabytes
