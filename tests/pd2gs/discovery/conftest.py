import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))  # the synthetic/fixture helpers beside the tests
