"""How every console script of the family ends (``rsart``, ``rsart-eval``, ``pd2gs``, ``rsart-leaderboard``):
one function, :func:`guarded`, so the exit codes and one-line messages cannot drift apart between them."""
from __future__ import annotations

import os
import sys
from typing import Callable

from .errors import RsartError, escape_controls
from .extras import from_import_error


def guarded(call: Callable[[], int | None], prog: str = "", interrupted: str = "interrupted") -> int:
    """Run a console script's work and end it the way every rsart-family command ends (``rsart``,
    ``rsart-eval``, ``pd2gs``, ``rsart-leaderboard``): the exit status of ``call()`` (None = 0); an
    :class:`~rsart.errors.RsartError` or a missing extra -> ``[prog: ]error: ...`` on stderr, exit 2;
    Ctrl-C -> ``interrupted``, exit 130; any other exception (a bug) -> one line naming it, exit 1, with the
    traceback only when ``RSART_DEBUG`` is set."""
    lead = f"{prog}: " if prog else ""
    try:
        return int(call() or 0)
    except RsartError as e:
        print(f"{lead}error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{lead}{interrupted}", file=sys.stderr)
        return 130
    except Exception as e:
        if (err := from_import_error(e)) is not None:  # a module of a missing extra: `pip install 'rsart[X]'`
            print(f"{lead}error: {err}", file=sys.stderr)
            return 2
        if os.environ.get("RSART_DEBUG"):
            raise
        print(f"{lead}internal error (please report; set RSART_DEBUG=1 for the traceback): "
              f"{type(e).__name__}: {escape_controls(str(e))}", file=sys.stderr)
        return 1
