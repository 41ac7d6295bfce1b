"""``rsart leaderboard add | build | serve | token``: the result store, the static site and the server.

Plugged into ``rsart`` through the entry-point group ``rsart.commands`` (``register(subparsers)``);
also runnable alone as ``python -m leaderboards.cli ...`` (or the ``rsart-leaderboard`` script).
Exit codes: 0 success, 2 invalid input or usage (message, no traceback).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rsart.console import guarded
from rsart.errors import RsartError

DB_HELP = "result store: a SQLAlchemy URL (e.g. postgresql://user@host/db) or a SQLite file path"


def _at_least(lo: int):
    def parse(s: str) -> int:
        try:
            v = int(s)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{s!r} is not an integer") from None
        if v < lo:
            raise argparse.ArgumentTypeError(f"must be >= {lo}")
        return v
    return parse


_positive = _at_least(1)


def _add(args) -> int:
    from .schema import open_engine
    from .store import add_scores

    engine = open_engine(args.db)
    for d in args.scores:
        sid, created = add_scores(engine, d, label=args.label)
        print(f"{d}: {'added as' if created else 'already stored as'} submission {sid}")
    return 0


def _build(args) -> int:
    import time

    from .exports import build_site
    from .schema import open_engine

    t = time.perf_counter()
    out = build_site(open_engine(args.db), args.out, plots=not args.no_plots, all_runs=args.all_runs)
    print(f"site written to {out} in {time.perf_counter() - t:.1f} s (open {out / 'index.html'})")
    return 0


def _serve(args) -> int:
    from .archive import ArchiveLimits
    from .schema import sqlite_path
    from .server import ServerConfig, serve
    from .worker import ScoringSettings

    if not (args.data / "index.json").is_file() and not (args.data / "meta.json").is_file():
        raise RsartError(f"{args.data}: not a dataset root (index.json) or an object folder (meta.json)")
    work = args.work
    if work is None:
        p = sqlite_path(args.db)
        if p is None:
            raise RsartError("--work DIR is required when --db is not a SQLite file")
        work = p.parent / f"{p.stem}-work"
    cfg = ServerConfig(db=args.db, data=args.data.resolve(), work=work.resolve(),
                       archive=ArchiveLimits(max_upload_bytes=int(args.max_upload_mb * 1024 ** 2),
                                             max_unpacked_bytes=int(args.max_unpacked_mb * 1024 ** 2)),
                       scoring=ScoringSettings(args.chamfer_samples, tuple(args.chamfer_seeds), args.states,
                                               args.max_mesh_mb))
    print(f"serving on http://{args.host}:{args.port}/ (work folder {cfg.work}, {args.workers} worker(s))",
          file=sys.stderr, flush=True)
    return serve(cfg, args.host, args.port, args.workers)


def _token_add(args) -> int:
    from .jobs import create_token
    from .schema import open_engine

    tok = create_token(open_engine(args.db), args.team, args.rate)
    print(tok)
    print(f"token for team {args.team!r} ({args.rate} uploads/hour); shown once, stored hashed", file=sys.stderr)
    return 0


def _token_revoke(args) -> int:
    from .jobs import revoke_team
    from .schema import open_engine

    n = revoke_team(open_engine(args.db), args.team)
    print(f"revoked {n} token(s) of team {args.team!r}")
    return 0 if n else 2


def _seeds(s: str) -> list[int]:
    try:
        return [int(x) for x in s.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{s!r} is not a comma list of integers") from None


DESCRIPTION = ("Leaderboards for rsart-eval scores (docs/leaderboard.md): one row per submission (run label, "
               "config hash), ranked by the penalised mean with the completion rate beside it. Published rows of "
               "the PD²GS paper are shown apart and never ranked with computed scores.")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``leaderboard`` and its actions to an argparse subparsers object (``rsart leaderboard ...``)."""
    p = sub.add_parser("leaderboard", help="result store, static leaderboard site and submission server",
                       description=DESCRIPTION)
    p.set_defaults(func=lambda a: (p.print_help(), 2)[1])
    add_actions(p.add_subparsers(dest="leaderboard_command", metavar="ACTION"))


def add_actions(lsub: argparse._SubParsersAction) -> None:
    """The actions add, build, serve and token (shared by ``rsart leaderboard`` and ``rsart-leaderboard``)."""
    a = lsub.add_parser("add", help="ingest rsart-eval output folders (scores.json); idempotent")
    a.add_argument("scores", nargs="+", type=Path, help="rsart-eval --out folder(s) or scores.json file(s)")
    a.add_argument("--db", required=True, help=DB_HELP)
    a.add_argument("--label", help="run label shown in the tables (default: the method block's \"run\", else "
                                   "#<submission id>)")
    a.set_defaults(func=_add)

    b = lsub.add_parser("build", help="write the static site (HTML, Markdown, CSV)")
    b.add_argument("--db", required=True, help=DB_HELP)
    b.add_argument("--out", required=True, type=Path, help="site folder (replaced atomically)")
    b.add_argument("--no-plots", action="store_true", help="skip the per-method PNG plots")
    b.add_argument("--all-runs", action="store_true",
                   help="rank every run of each method (default: each method's best-ranked run; every run is "
                        "always on the method's page)")
    b.set_defaults(func=_build)

    s = lsub.add_parser("serve", help="run the submission server with scoring workers")
    s.add_argument("--db", required=True, help=DB_HELP)
    s.add_argument("--data", required=True, type=Path, help="ground-truth dataset root that uploads are scored on")
    s.add_argument("--work", type=Path, help="uploads and scores folder (default: <db file>-work beside a SQLite db)")
    s.add_argument("--host", default="127.0.0.1")
    s.add_argument("--port", type=int, default=8000)
    s.add_argument("--workers", type=_at_least(0), default=2,
                   help="scoring processes (default 2; 0 = accept and queue uploads, score them later)")
    s.add_argument("--max-upload-mb", type=float, default=200.0, help="largest zip accepted (default 200)")
    s.add_argument("--max-unpacked-mb", type=float, default=1024.0, help="largest unpacked size (default 1024)")
    s.add_argument("--max-mesh-mb", type=float, default=200.0, help="largest mesh file (default 200)")
    s.add_argument("--chamfer-samples", type=_positive, default=10000)
    s.add_argument("--chamfer-seeds", type=_seeds, default=[0, 1, 2])
    s.add_argument("--states", default="start,end")
    s.set_defaults(func=_serve)

    t = lsub.add_parser("token", help="team tokens for the server (stored hashed)")
    t.set_defaults(func=lambda a: (t.print_help(), 2)[1])
    tsub = t.add_subparsers(dest="token_command", metavar="ACTION")
    ta = tsub.add_parser("add", help="create a token for TEAM and print it once")
    ta.add_argument("team")
    ta.add_argument("--db", required=True, help=DB_HELP)
    ta.add_argument("--rate", type=_positive, default=20, help="uploads per hour (default 20)")
    ta.set_defaults(func=_token_add)
    tr = tsub.add_parser("revoke", help="revoke every token of TEAM")
    tr.add_argument("team")
    tr.add_argument("--db", required=True, help=DB_HELP)
    tr.set_defaults(func=_token_revoke)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="rsart-leaderboard", description=DESCRIPTION)
    parser.set_defaults(func=lambda a: (parser.print_help(), 2)[1])
    add_actions(parser.add_subparsers(dest="leaderboard_command", metavar="ACTION"))
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    return guarded(lambda: args.func(args))


if __name__ == "__main__":
    sys.exit(main())
