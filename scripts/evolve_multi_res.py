"""ER-MRL's evolve_multi_res.py: evolve several reservoirs read by one agent, on one environment.

Run from anywhere, e.g. `python scripts/evolve_multi_res.py --help`; docs/reservoirs.md.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the repository root, for `reservoirs`

from reservoirs.launch import run_script

if __name__ == "__main__":
    sys.exit(run_script("evolve_multi_res"))
