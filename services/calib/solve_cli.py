"""``stb calib solve PASSPOINTS.csv``: a camera's pose from passpoints (paper §2.2).

PASSPOINTS.csv has the header X,Y,Z,u,v (mm, px) and optionally t (the image's time in s on
the camera clock) and zoom (the zoom step). With --mocap-track TRACK.csv (header t,X,Y,Z on
the mocap clock) a passpoint's marker position is the track at t + time_offset_s, and the
offset is fitted. Passpoints at two or more zoom steps (what ``stb calib collect --zooms``
stores) give the lens too: a focal length and the distortion per zoom, one pose.
Exit status: 0 solved, 2 bad arguments or input, 3 no trustworthy pose.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from services.args import Parser, plain

if TYPE_CHECKING:  # imported once the flags are parsed: --help answers at once
    from common.camera import Pose
    from common.passpoints import Passpoints
    from services.calib.solve import Options

EXIT_BAD_INPUT = 2
EXIT_NO_POSE = 3


def main(argv: Sequence[str] | None = None) -> int:
    parser = Parser(prog="stb calib solve", description=plain(__doc__ or ""),
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("passpoints", type=Path, help="CSV: X,Y,Z,u,v[,t][,zoom]")
    parser.add_argument("--initial", help="rough pose tx,ty,tz,rx,ry,rz (mm, deg) for the "
                        "paper's searches; method auto needs none")
    parser.add_argument("--method", choices=["auto", "cmaes", "simplex"], default="auto",
                        help="auto: SQPnP + RANSAC + LM, no guess (default); cmaes / simplex: "
                             "the paper's searches from --initial")
    focal = parser.add_mutually_exclusive_group()
    focal.add_argument("--focal-px", type=float, default=None,
                       help="focal length of the images in pixels (default the AXIS 215's "
                       "3.8 mm at wide in its picture: 743)")
    focal.add_argument("--fit-focal", action="store_true", help="fit the focal length too")
    parser.add_argument("--picture", type=_picture_size, default=(704, 576), metavar="WxH",
                        help="the snapshots' size in pixels (default 704x576, the AXIS 215's)")
    parser.add_argument("--mocap-track", type=Path, help="CSV: t,X,Y,Z; fits the clock offset")
    parser.add_argument("--max-offset-s", type=float, default=0.5,
                        help="largest clock offset searched (default 0.5 s)")
    parser.add_argument("--inlier-px", type=float, default=10.0,
                        help="passpoints farther than this from the fit are rejected (default 10)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--plot", type=Path, metavar="DIR",
                        help="write fitness.png (searches) and residuals.png here")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    args = parser.parse_args(argv)
    from common.passpoints import CalibrationError, read_passpoints, read_track
    from services.calib.solve import Options, solve, warm_up

    warm_up()  # the time the summary reports is the solve's
    try:
        points = read_passpoints(args.passpoints)
        options = Options(method=args.method, initial=_parse_pose(args.initial),
                          **({} if args.focal_px is None else {"focal_px": args.focal_px}),
                          fit_focal=args.fit_focal, picture_px=args.picture,
                          track=read_track(args.mocap_track) if args.mocap_track else None,
                          max_time_offset_s=args.max_offset_s, inlier_px=args.inlier_px,
                          seed=args.seed)
    except (CalibrationError, ValueError) as err:
        print(f"stb calib solve: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if len(points.by_zoom()) > 1:
        return _solve_zooms(points, options, args)
    try:
        solution = solve(points, options)
    except CalibrationError as err:
        print(f"stb calib solve: {err}", file=sys.stderr)
        return EXIT_NO_POSE
    report = solution.report()
    if args.plot:
        from services.calib.plot import write_plots

        report["plots"] = [str(p) for p in write_plots(solution, points, args.plot)]
    print(json.dumps(report) if args.json else _human(report))
    return 0


def _solve_zooms(points: Passpoints, options: Options, args: argparse.Namespace) -> int:
    from common.passpoints import CalibrationError
    from services.calib.zoom_fit import solve_zooms

    try:
        fit, first = solve_zooms(points.by_zoom(), options)
    except CalibrationError as err:
        print(f"stb calib solve: {err}", file=sys.stderr)
        return EXIT_NO_POSE
    report = fit.report() | {"time_offset_s": round(first.time_offset_s or 0.0, 5)}
    if args.plot:
        from services.calib.plot import write_lens_plot

        report["plots"] = [str(write_lens_plot(fit, args.plot / "lens.png"))]
    print(json.dumps(report) if args.json else _human_zooms(report))
    return 0


def _human_zooms(report: dict) -> str:
    lines = [*_pose_lines(report),
             f"error       {report['mean_error_px']:.2f} px mean over every zoom's inliers",
             "zoom    focal px  k1       k2       p1        p2        k3       px   points"]
    for at in report["lens"]:
        k1, k2, p1, p2, k3 = at["distortion"]
        lines.append(f"{at['zoom']:<7d} {at['focal_px']:8.1f}  {k1:+.4f} {k2:+.4f} {p1:+.5f} "
                     f"{p2:+.5f} {k3:+.4f} {at['mean_error_px']:5.2f} {at['passpoints']:4d}")
    return "\n".join(lines + _clock_and_plots(report))


def _picture_size(text: str) -> tuple[int, int]:
    width, _, height = text.lower().partition("x")
    if not (width.isdigit() and height.isdigit() and 0 < int(width) <= 8192
            and 0 < int(height) <= 8192):
        raise argparse.ArgumentTypeError(f"{text!r}: a picture's size is WIDTHxHEIGHT in "
                                         "pixels, as 1920x1080")
    return int(width), int(height)


def _parse_pose(text: str | None) -> Pose | None:
    from common.camera import Pose

    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError as err:
        raise ValueError(f"--initial {text!r}: {err}") from err
    if len(values) != 6:
        raise ValueError(f"--initial needs six numbers tx,ty,tz,rx,ry,rz, got {len(values)}")
    return Pose(*values)


def _pose_lines(report: dict) -> list[str]:
    x, y, z = report["position_mm"]
    rx, ry, rz = report["orientation_deg"]
    return [f"position    {x:9.1f} {y:9.1f} {z:9.1f} mm",
            f"orientation {rx:9.3f} {ry:9.3f} {rz:9.3f} deg (R = Rx·Ry·Rz)"]


def _clock_and_plots(report: dict) -> list[str]:
    lines = [f"clock       mocap = camera + {report['time_offset_s'] * 1e3:.1f} ms"] \
        if "time_offset_s" in report else []
    return lines + [f"plot        {p}" for p in report.get("plots", [])]


def _human(report: dict) -> str:
    lines = [*_pose_lines(report),
             "1σ          ±{:.1f} ±{:.1f} ±{:.1f} mm, ±{:.3f} ±{:.3f} ±{:.3f} deg".format(
                 *report["position_std_mm"], *report["orientation_std_deg"]),
             f"focal       {report['focal_px']:.1f} px",
             f"error       {report['mean_error_px']:.2f} px mean over "
             f"{len(report['inliers'])} inliers; rejected {report['rejected'] or 'none'}",
             f"method      {report['method']}, {report['evaluations']} evaluations, "
             f"{report['seconds'] * 1e3:.1f} ms"]
    return "\n".join(lines + _clock_and_plots(report))
