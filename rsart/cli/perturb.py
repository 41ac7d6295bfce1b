"""``rsart perturb-poses OBJECT --rot-deg U --trans V --seed S --out COPY [--poses gt|colmap]`` (rsart.perturb).

Camera poses only; joints are perturbed by ``rsart-eval --make-gt-submission --perturb-joints``. The old
name ``rsart perturb`` still works and prints a deprecation warning."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

NAME = "perturb-poses"
OLD_NAME = "perturb"  # deprecated alias (until 0.3): it was easy to confuse with rsart-eval's joint perturbation

DESCRIPTION = """\
Copy an object folder with noisy or estimated camera poses, so any method can be run under pose
errors (the PD2GS paper's study: (1 deg, 0.02) and (3 deg, 0.05), and COLMAP poses).

Noise: each camera is rotated in its own frame by a rotation vector whose components are
N(0, rot-deg^2) degrees, and its centre moved by N(0, trans^2) per axis in the object's units
(metres, or scene units for PartNet-Mobility objects). --poses colmap first replaces the true poses
with SfM estimates (pycolmap, via the capture_tools package), placed in the object frame by a
similarity fitted to the true camera centres; views SfM cannot register are left out.
The copy records what was done in meta.json ("camera_poses") and every cameras.json."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(NAME, aliases=[OLD_NAME],
                       help=f"copy an object with noisy or COLMAP camera poses ('{OLD_NAME}' is a deprecated alias)",
                       description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("object", type=Path, help="object folder (meta.json + states/)")
    p.add_argument("--rot-deg", type=float, default=0.0, help="rotation noise sigma per axis, degrees (default 0)")
    p.add_argument("--trans", type=float, default=0.0, help="translation noise sigma per axis, object units (default 0)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--poses", choices=("gt", "colmap"), default="gt", help="start from the true poses or SfM estimates")
    p.add_argument("--out", type=Path, required=True, help="folder for the copy (new or empty; a non-empty one needs --overwrite)")
    p.add_argument("--overwrite", action="store_true")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from ..perturb import perturb_object

    if getattr(args, "command", None) == OLD_NAME:
        print(f"warning: 'rsart {OLD_NAME}' is deprecated; use 'rsart {NAME}' (camera poses). Joints are perturbed "
              "by 'rsart-eval --make-gt-submission --perturb-joints'.", file=sys.stderr)

    summary = perturb_object(args.object, args.out, args.rot_deg, args.trans, args.seed, args.poses, args.overwrite)
    print(json.dumps(summary, indent=2))
    return 0
