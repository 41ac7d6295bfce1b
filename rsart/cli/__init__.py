"""The ``rsart`` command line: one entry point, one module per subcommand.

Each module in :data:`COMMANDS` exposes ``register(subparsers)``, which adds its subparser and
sets ``func`` (called with the parsed args; returns an exit code). :func:`rsart.console.guarded` ends every
rsart-family console script: errors rsart raises on purpose (:class:`rsart.errors.RsartError`) are
printed without a traceback and exit 2; a bug is one line and exit 1 (``RSART_DEBUG=1``: the traceback).
"""
from __future__ import annotations

import argparse
import importlib
import sys

from ..console import guarded

#: Subcommand modules (in --help order). A module that fails to import is reported, not fatal.
COMMANDS = [
    "rsart.cli.basic",        # validate, verify, info
    "rsart.cli.generate",     # generate (procedural twins, rsart-synth)
    "rsart.cli.render",       # render (capture simulator)
    "rsart.cli.show",         # show (pictures)
    "rsart.cli.convert",      # convert (PartNet-Mobility, URDF, USD)
    "rsart.cli.validate_submission",  # validate-submission
    "rsart.cli.adapters",     # adapters, export, import (method plug-ins, entry points rsart.adapters)
    "rsart.cli.perturb",      # perturb (camera-pose noise / COLMAP poses)
    "rsart.cli.doctor",       # doctor (what this install can do)
]

DESCRIPTION = """\
rsart: datasets and benchmark for articulated-object reconstruction (RS-Art format).

Conventions everywhere: metres and radians (degrees only in metric reports); world frame =
the object's base frame, z up; part meshes stored at the rest configuration (all joints 0);
cameras OpenCV (x right, y down, z forward) with camera-to-world extrinsics; depth PNGs are
16-bit millimetres (0 = no measurement); masks are part index + 1 (0 = background).
Exit codes: 0 success, 1 problems found (verify), 2 invalid input or usage.
"""


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = argparse.ArgumentParser(prog="rsart", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"rsart {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        try:
            mod = importlib.import_module(name)
        except ModuleNotFoundError as e:
            if e.name == name:  # subcommand not installed in this build
                continue
            raise
        mod.register(sub)
    _register_plugins(sub)
    return parser


def _register_plugins(sub) -> None:
    """Subcommands from other installed packages: entry points in group ``rsart.commands``, each a callable
    ``register(subparsers)`` (rsart imports none of those packages itself). A broken plug-in is reported."""
    from importlib.metadata import entry_points

    for ep in sorted(entry_points(group="rsart.commands"), key=lambda e: e.name):
        try:
            ep.load()(sub)
        except Exception as e:  # one broken plug-in must not break the CLI
            print(f"warning: rsart.commands plug-in {ep.name!r} ({ep.value}) failed: {type(e).__name__}: {e}",
                  file=sys.stderr)


def run(func, args) -> int:
    """Call a subcommand ``func(args)`` under :func:`guarded`."""
    return guarded(lambda: func(args))


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    return run(args.func, args)


if __name__ == "__main__":
    sys.exit(main())
