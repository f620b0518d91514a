"""The detector's loop built ahead of time (``common/markers_aot.py``, built by ``make``): the
detector loads it with neither numba nor LLVM in the process, it gives what numba's JIT
gives, and a build of another version of the loop is never loaded."""

from __future__ import annotations

import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from benchmarks.markers import make_frames
from common import markers, markers_aot

ROOT = Path(__file__).resolve().parents[2]
needs_a_compiler = pytest.mark.skipif(shutil.which("c++") is None,
                                      reason="no C++ compiler: the detector uses numba's JIT")


@pytest.fixture
def fresh_loader() -> Iterator[None]:
    markers._threshold_kernel.cache_clear()
    yield
    markers._threshold_kernel.cache_clear()


@needs_a_compiler
def test_the_detector_runs_without_numba_or_llvm() -> None:
    assert markers_aot.module_file(markers_aot.KERNEL_SOURCE.parent).is_file(), \
        "the loop is not built for this source: make (or python -m common.markers_aot)"
    code = ("import sys; from common.markers import warm_up, kernel_origin; warm_up(); "
            "print(kernel_origin(), 'numba' in sys.modules, 'llvmlite' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, timeout=60, check=True).stdout.split()
    assert out == ["built", "ahead", f"(common.{markers_aot.module_name()})", "False", "False"]


@needs_a_compiler
def test_the_loop_built_ahead_gives_what_the_jit_gives(fresh_loader: None) -> None:
    from common.markers_kernel import threshold_kernel as jit

    ahead = markers._threshold_kernel()
    assert ahead is not jit, "the module built ahead is loaded"
    frames = make_frames(40, seed=11, markers=(0, 5), reflections=(0, 4))
    thresholds = markers._thresholds(230, 203, 5)
    for frame in frames:
        args = (frame, markers._band_maxima(frame), markers.BAND_ROWS, thresholds, 2,
                markers._SMALL_AREA, 1.21, 3, 20000)
        out_ahead, out_jit = np.zeros((256, 8)), np.zeros((256, 8))
        assert ahead(*args, out_ahead) == jit(*args, out_jit)
        assert np.array_equal(out_ahead, out_jit)


def test_a_build_of_another_loop_is_not_loaded(fresh_loader: None,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(markers_aot, "module_name", lambda: "_markers_kernel_000000000000")
    assert markers.kernel_origin() == "numba's JIT"
    frame = np.zeros((64, 64), np.uint8)
    frame[20:26, 30:36] = 250
    assert markers.detect(frame).status == "ok"


def test_the_name_follows_the_source(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    source = tmp_path / "markers_kernel.py"
    source.write_text("x = 1\n")
    monkeypatch.setattr(markers_aot, "KERNEL_SOURCE", source)
    first = markers_aot.module_name()
    source.write_text("x = 2\n")
    assert markers_aot.module_name() != first
    assert markers_aot.module_file(tmp_path).name.startswith(markers_aot.module_name() + ".")
