import sys

from rsart.cli import main

sys.exit(main())
