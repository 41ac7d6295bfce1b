"""``rsart doctor``: what this install can do (versions, extras, rendering, torch/numba, GPU, cache)."""
from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("doctor", help="what this install can do, and how to get what it cannot",
                       description="Print the Python and package versions, which extras are installed (and the "
                                   "pip command for each missing one), whether headless rendering works on EGL "
                                   "and OSMesa (a 1-frame render in a subprocess with a timeout), whether torch "
                                   "and numba load, the CPU cores, the GPU and gsplat, and the cache folder "
                                   "($RSART_CACHE, else ~/.cache/rsart). Writes nothing. "
                                   "Exit 0 when the core (load, validate, verify, generate, rsart-eval) works.")
    p.add_argument("--no-gl", action="store_true", help="skip the rendering test")
    p.add_argument("--gl-timeout", type=float, default=30.0, help="seconds per rendering test (default 30)")
    p.set_defaults(func=_doctor)


def _doctor(args) -> int:
    from ..doctor import format_report, run_checks

    checks, core_ok = run_checks(gl=not args.no_gl, gl_timeout=args.gl_timeout)
    print(format_report(checks))
    print("core works" if core_ok else "the core does not work: reinstall with pip install rsart")
    return 0 if core_ok else 1
