"""Which test files may share the CPU with a neighbour: the suite's two phases.

scripts/test.sh runs pytest twice: `MEXONE_TEST_PHASE=parallel` with pytest-xdist on every core
(`-n auto --dist loadfile`: a file's tests on one worker, its module fixtures built once) for the
files in SHARES_THE_CPU, then `MEXONE_TEST_PHASE=serial`, one test at a time, for all the others
(tests/conftest.py deselects by phase; unset, a plain `pytest` runs every test one at a time).

Listed (each file read, not guessed): tests that compute -- physics, fits, grading, parsing, the
docs build -- and hold the wall clock to nothing but generous timeouts (a graded run's time_limit
is 5-10x its measured run; a controller's overrun is its update's own CPU time, not the waits
for a CPU a neighbour causes: control/watchdog.py's own_time). Not listed, so run alone:
real-time pacing and RTF, page and browser timing, a student's controller in a paced lab, ROS
and its clocks, the hub, signals sent at a moment, "took < N s" checks, Ray's clusters (their
start has timeouts of its own), and the wheel's session venv (built once, in the serial phase).
A new test file runs alone until someone reads it and lists it here; tests/test_phases.py keeps
the listed ones off the browser, ROS, Ray and the venv.
"""

from __future__ import annotations

from pathlib import Path

TESTS = Path(__file__).resolve().parent
PHASES = ("parallel", "serial")
SHARES_THE_CPU = (  # paths under tests/; a folder ends in "/"
    "walking/test_stack.py", "walking/test_pushes.py", "walking/test_parts.py",
    "walking/test_worlds.py",
    "identify/test_identify.py", "identify/test_hostile_bags.py", "identify/test_excitation.py",
    "exercises/test_course.py", "exercises/test_course_5_10.py", "exercises/test_course_robust.py",
    "exercises/test_walking_exercises.py", "exercises/test_method_checks.py",
    "exercises/test_reports.py", "exercises/test_grade_outputs.py", "exercises/test_requires.py",
    "exercises/test_autograder_pieces.py", "exercises/test_report_oracles.py",
    "design/test_robust.py", "design/test_lqr_balance.py", "design/test_deploy.py",
    "design/test_linear.py", "design/test_check_deployed.py", "design/test_design_files.py",
    "physics/test_mex_one_physics.py", "robots/test_mex_one_looks.py",
    "cli/test_help.py",
    "motion/test_ik.py",
    "description/test_any_robot.py", "description/test_check_rules.py",
    "description/test_convert.py", "description/test_mesh_reader.py",
    "description/test_mjcf_in.py", "description/test_sdf_versions.py",
    "description/test_value_conflicts.py",
    "dynamics/",
    "record/test_record.py", "record/test_recover.py",
    "test_docs.py", "test_examples.py", "test_layers.py", "cli/test_example_robot.py",
    "editor/test_editor_hostile.py", "control/test_chained_controllers.py", "test_phases.py",
    "control/test_one_writer.py", "sandbox/test_wire.py",
    "test_public_api.py", "test_wheelenv.py",
)


def shares_the_cpu(path: Path) -> bool:
    """Whether the test file at `path` runs in the parallel phase."""
    rel = path.resolve().relative_to(TESTS).as_posix()
    return any(rel == entry or (entry.endswith("/") and rel.startswith(entry))
               for entry in SHARES_THE_CPU)


def missing() -> list[str]:
    """The entries of SHARES_THE_CPU that name no file or folder (renamed or removed)."""
    return [entry for entry in SHARES_THE_CPU if not (TESTS / entry).exists()]
