"""Every benchmark in one run, as `mexone bench` prints it (see mexone/bench.py for the rows).

    python benchmarks/run_all.py [--quick] [--json]

Record the output in benchmarks/RESULTS.md with the date when a change affects speed.
"""

import sys

from mexone.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", *sys.argv[1:]]))
