"""leaderboards: a result store for rsart scores, the PD²GS paper's published rows, a static site and a
submission server.

* :mod:`leaderboards.store` — SQLAlchemy result store (SQLite by default, any SQLAlchemy URL);
* :mod:`leaderboards.paper` — the paper's published tables (``leaderboards/data/paper/*.json``);
* :mod:`leaderboards.tracks` — tracks derived from a submission's ``method`` block;
* :mod:`leaderboards.site` — the static site (HTML + Markdown + CSV);
* :mod:`leaderboards.server` / :mod:`leaderboards.worker` — upload server and scoring workers;
* :mod:`leaderboards.cli` — ``rsart leaderboard add | build | serve | token``.

Docs: docs/leaderboard.md. ``rsart`` never imports this package; the CLI is plugged in through the
``rsart.commands`` entry-point group.
"""
__version__ = "0.1.0"
