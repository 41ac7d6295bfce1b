"""``rsart capture ...``: the capture tools as an rsart subcommand (entry point ``rsart.commands``:
``capture = "capture_tools.cli:register"``; rsart itself never imports this package).

* ``rsart capture assemble RAW_DIR --twin TWIN [--states states.yaml] --out OBJECT_DIR``
* ``rsart capture raw OBJECT_DIR --layout frames|video|bag --out RAW_DIR`` (a rendered object as a raw capture,
  poses withheld -- for trying the tools on the simulator's booth captures)
* ``rsart capture info RECORDING`` (intrinsics, depth scale, frame count of a recording)
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

HELP = """\
Real capture -> RS-Art object folder. Conventions: metres and radians; cameras OpenCV (x right, y down,
z forward), camera-to-world; output poses are in the twin's base frame (the twin is registered to the
captured depth). Recordings: RealSense frame folders (color/, depth/, intrinsics.json), colour video +
depth/ folder, or RealSense Viewer .bag files. Docs: docs/capture.md."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("capture", help="real captures: RealSense recordings -> RS-Art object folder",
                       description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    csub = p.add_subparsers(dest="capture_command", metavar="ACTION")
    p.set_defaults(func=lambda a: (p.print_help(), 2)[1])

    a = csub.add_parser("assemble", help="raw capture + capture log + twin -> object folder",
                        description="Select frames, key the booth, estimate camera poses (SfM, metric scale from "
                                    "depth), register the twin and write OBJECT_DIR (meta.json, twin/, states/, "
                                    "capture.json with every step's figures).\n\n" + HELP,
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    a.add_argument("raw", type=Path, help="raw capture folder (one recording per state)")
    a.add_argument("--twin", type=Path, required=True, help="twin: .urdf, .usd/.usda/.usdc or an object folder")
    a.add_argument("--states", type=Path, default=None, help="capture log (default RAW/states.yaml)")
    a.add_argument("--out", type=Path, required=True, help="object folder to write")
    a.add_argument("--views", type=int, default=30, help="frames selected per state (default 30)")
    a.add_argument("--no-grabcut", action="store_true", help="chroma key without the GrabCut edge refinement")
    a.add_argument("--charuco", default=None, metavar="SXxSY,SQUARE,MARKER[,DICT]",
                   help="a ChArUco board on the pedestal gives the metric scale, e.g. 5x7,0.04,0.03,DICT_5X5_100 "
                        "(squares, square and marker side in metres)")
    a.add_argument("--sfm", choices=("per-state", "joint"), default=None,
                   help="camera poses: one SfM per state, or one joint SfM over all states tied only by the "
                        "static base (default: joint; docs/capture.md)")
    a.add_argument("--seed", type=int, default=0)
    a.add_argument("--overwrite", action="store_true")
    a.set_defaults(func=_assemble)

    r = csub.add_parser("raw", help="write a rendered object folder as a raw capture (poses withheld)")
    r.add_argument("object", type=Path, help="object folder rendered by `rsart render`")
    r.add_argument("--layout", choices=("frames", "video", "bag"), default="frames")
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--states", nargs="*", default=None, help="state ids (default: every rendered state)")
    r.add_argument("--codec", choices=("FFV1", "MJPG"), default="FFV1",
                   help="video layout: FFV1 lossless (color.mkv, default) or MJPG lossy (color.avi)")
    r.set_defaults(func=_raw)

    i = csub.add_parser("info", help="intrinsics, depth scale and frame count of a recording")
    i.add_argument("recording", type=Path)
    i.set_defaults(func=_info)


def _assemble(args) -> int:
    from rsart.errors import RsartError

    from .assemble import assemble
    from .chroma import ChromaSettings
    from .pipeline import CaptureSettings

    if args.views < 3:
        raise RsartError(f"--views must be at least 3, got {args.views}")
    s = CaptureSettings(n_views=args.views, chroma=ChromaSettings(grabcut=not args.no_grabcut), seed=args.seed,
                        board=_board(args.charuco) if args.charuco else None, **({"sfm": args.sfm} if args.sfm else {}))
    rep = assemble(args.raw, args.twin, args.states, args.out, s, overwrite=args.overwrite)
    bad = [sid for sid, r in rep["states"].items() if r["registration"]["icp_fitness"] < 0.7]
    print(f"wrote {args.out}")
    if bad:
        print(f"warning: twin registration fits poorly in states {bad} (fitness < 0.7); see {args.out}/capture.json")
        return 1
    return 0


def _board(text: str):
    from rsart.errors import RsartError

    from .board import BoardSpec

    try:
        parts = text.split(",")
        sx, sy = (int(x) for x in parts[0].lower().split("x"))
        spec = BoardSpec(sx, sy, float(parts[1]), float(parts[2]), parts[3] if len(parts) > 3 else "DICT_5X5_100")
    except (ValueError, IndexError):
        raise RsartError(f"--charuco {text!r}: expected SXxSY,SQUARE,MARKER[,DICT], e.g. 5x7,0.04,0.03") from None
    if not (spec.squares_x > 1 and spec.squares_y > 1 and 0 < spec.marker < spec.square):
        raise RsartError(f"--charuco {text!r}: needs > 1 squares each way and 0 < marker < square")
    spec.board()  # unknown dictionary -> RsartError
    return spec


def _raw(args) -> int:
    from .raw_writer import write_raw_capture

    path = write_raw_capture(args.object, args.out, args.layout, args.states, codec=args.codec)
    print(f"wrote {args.out} ({args.layout}); capture log {path}")
    return 0


def _info(args) -> int:
    from .recording import open_recording

    rec = open_recording(args.recording)
    print(json.dumps({"recording": str(args.recording), "frames": len(rec), "intrinsics": rec.intrinsics.to_dict(),
                      "depth_scale": rec.depth_scale,
                      "depth_aligned_on_read": rec.calibration.depth_to_colour is not None}, indent=2))
    return 0
