"""The fork server of exercises.isolate (`python -m mexone.exercises.child --server FD`): a fresh
interpreter, so nothing of the grader's is in it, or in the runs it forks."""

import sys

from mexone.exercises.isolate import serve

__all__: list[str] = []

if __name__ == "__main__" and sys.argv[1:2] == ["--server"]:
    serve(int(sys.argv[2]))
