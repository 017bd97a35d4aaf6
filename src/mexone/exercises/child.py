"""The isolated child of exercises.isolate.run_isolated: `python -m mexone.exercises.child
CALL_FD RESULT_FD CPU_S MEMORY_MB` (a fresh interpreter, so nothing of the grader's is in it)."""

import sys

from mexone.exercises.isolate import child_main

if __name__ == "__main__":
    child_main(sys.argv[1:])
