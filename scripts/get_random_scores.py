"""ER-MRL's get_random_scores.py: the mean return of a random agent, the R_random of the normalised score.

Run from anywhere, e.g. `python scripts/get_random_scores.py --help`; docs/reservoirs.md.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the repository root, for `reservoirs`

from reservoirs.launch import run_script

if __name__ == "__main__":
    sys.exit(run_script("get_random_scores"))
