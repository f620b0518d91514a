"""The marker detector's compiled loop, built ahead of time: ``common/markers_kernel.py``
through numba's AOT compiler into an extension module beside it, which the detector loads
without numba or LLVM (133 MB less in each service that detects: docs/benchmarks.md,
"Memory").

    python -m common.markers_aot [--output-dir DIR]

``make`` runs it after installing and whenever markers_kernel.py changes, the Docker image's
build stage too. Numba compiles its helpers (C, and its runtime in C++) and links the module
with the machine's compiler (``c++``: Debian's g++); without one this says so, exits 0, and
the detector keeps numba's JIT (the same loop, compiled at the first start and cached on
disk). The module is built for the architecture's generic CPU, so an image
built on one machine runs on another. Its name carries a hash of the kernel's source
(``_markers_kernel_<hash>``): a module built from another version of the kernel is never
loaded.
"""

from __future__ import annotations

import argparse
import hashlib
import shutil
import sys
import sysconfig
import time
from pathlib import Path

KERNEL_SOURCE = Path(__file__).with_name("markers_kernel.py")
SIGNATURE = ("Tuple((int64, int64))(uint8[:, ::1], uint8[::1], int64, int64[::1], int64, "
             "int64, float64, int64, int64, float64[:, ::1])")
"""``threshold_kernel``'s argument types as ``common.markers.detect`` passes them."""


def module_name() -> str:
    """The compiled module's name for the kernel's source as it is now."""
    digest = hashlib.sha256(KERNEL_SOURCE.read_bytes()).hexdigest()[:12]
    return f"_markers_kernel_{digest}"


def module_file(folder: Path) -> Path:
    return folder / (module_name() + (sysconfig.get_config_var("EXT_SUFFIX") or ".so"))


def build(output_dir: Path) -> Path:
    """Compile the kernel into ``output_dir``; old builds of other kernel versions there are
    removed. Raises RuntimeError when there is no C compiler."""
    if shutil.which("c++") is None:
        raise RuntimeError("no C/C++ compiler (c++; numba's runtime is C++) to build the module")
    from numba.pycc import CC

    from common import markers_kernel

    compiler = CC(module_name())
    compiler.output_dir = str(output_dir)
    compiler.export("threshold_kernel", SIGNATURE)(markers_kernel.threshold_kernel.py_func)
    compiler.compile()
    built = module_file(output_dir)
    for old in output_dir.glob("_markers_kernel_*"):
        if old != built:
            old.unlink()
    return built


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--output-dir", type=Path, default=KERNEL_SOURCE.parent,
                        help="where the module goes (default: beside markers_kernel.py)")
    args = parser.parse_args(argv)
    target = module_file(args.output_dir)
    if target.is_file():
        print(f"markers_aot: {target} is current", file=sys.stderr)
        return 0
    started = time.perf_counter()
    try:
        built = build(args.output_dir)
    except Exception as err:  # noqa: BLE001 - any failure leaves the JIT, which works
        print(f"markers_aot: not built ({err}); the marker detector uses numba's JIT "
              "(about 130 MB more in each service that detects)", file=sys.stderr)
        return 0
    print(f"markers_aot: built {built} in {time.perf_counter() - started:.0f} s",
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
