"""``stb detect IMAGE... [--json]``: run the marker detector on image files (paper §2.1)."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from services.args import Parser, plain


def main(argv: Sequence[str] | None = None) -> int:
    parser = Parser(prog="stb detect", description=plain(__doc__ or ""))
    parser.add_argument("images", nargs="+", type=Path, metavar="IMAGE")
    parser.add_argument("--threshold", type=int, default=230, help="first gray threshold")
    parser.add_argument("--t-lim", type=int, default=203, help="lowest threshold (paper: 203)")
    parser.add_argument("--step", type=int, default=5, help="threshold decrement")
    parser.add_argument("--r-lim", type=float, default=1.21, help="roundness limit (1.21)")
    parser.add_argument("--l-min", type=int, default=2, help="shortest run, pixels")
    parser.add_argument("--min-area", type=int, default=3)
    parser.add_argument("--max-area", type=int, default=20000)
    parser.add_argument("--max-markers", type=int, default=1,
                        help="more valid markers than this is 'too_many'")
    parser.add_argument("--annotate", type=Path, metavar="DIR",
                        help="write each image with its regions drawn to DIR")
    parser.add_argument("--json", action="store_true", help="one JSON object per image")
    args = parser.parse_args(argv)
    if args.annotate:
        args.annotate.mkdir(parents=True, exist_ok=True)
    failed = False
    for path in args.images:
        try:
            out = _one(path, args)
        except ValueError as err:
            out, failed = {"image": str(path), "error": str(err)}, True
        print(json.dumps(out) if args.json else _text(out), flush=True)
    return 1 if failed else 0


def _one(path: Path, args: argparse.Namespace) -> dict:
    import cv2  # after the flags are parsed: --help answers at once

    from common.markers import annotate, detect

    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise ValueError("not a readable image file")
    if image.ndim == 3:  # colour files are read as BGR(A); the detector wants gray
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2GRAY if image.shape[2] == 4
                             else cv2.COLOR_BGR2GRAY)
    result = detect(image, threshold=args.threshold, t_lim=args.t_lim, step=args.step,
                    r_lim=args.r_lim, l_min=args.l_min, min_area=args.min_area,
                    max_area=args.max_area, max_markers=args.max_markers)
    out = {"image": str(path), "status": result.status, "threshold": result.threshold,
           "markers": [m._asdict() for m in result.markers]}
    if args.annotate:
        target = args.annotate / f"{path.stem}.annotated.png"
        cv2.imwrite(str(target), annotate(image, result))
        out["annotated"] = str(target)
    return out


def _text(out: dict) -> str:
    if "error" in out:
        return f"{out['image']}: error: {out['error']}"
    lines = [f"{out['image']}: {out['status']} (threshold {out['threshold']})"]
    lines += [f"  u={m['u']:.2f} v={m['v']:.2f} radii={m['radius_long']:.2f}/"
              f"{m['radius_short']:.2f} angle={m['angle_deg']:.1f} roundness="
              f"{m['roundness']:.3f} area={m['area']}" for m in out["markers"]]
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
