"""ER-MRL's test_generalization.py: train PPO with and without reservoirs evolved on other environments.

Run from anywhere, e.g. `python scripts/test_generalization.py --help`; docs/reservoirs.md.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the repository root, for `reservoirs`

from reservoirs.launch import run_script

if __name__ == "__main__":
    sys.exit(run_script("test_generalization"))
