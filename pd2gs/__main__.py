"""``python -m pd2gs`` = the ``pd2gs`` console script."""
import sys

from pd2gs.cli import main

sys.exit(main())
