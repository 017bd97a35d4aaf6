"""Every ```bash and ```python block in README.md and docs/**/*.md runs, from the wheel installed
in a fresh venv (the session's `venv`, tests/wheelenv.py), in a scratch folder per page, each
within its time budget; blocks marked `<!-- needs: ros1 -->` or `display` run with a roscore or
under Xvfb (skipped where those are missing: a failure in CI). The convention is in
tests/docblocks.py and docs/contributing.md. A page gone stale (tests/data/docs/stale.md) fails.
"""

from __future__ import annotations

import os
import re
import resource
import sys
import time
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import pytest

pytest.importorskip("markdown_it", reason="the docs extra (markdown-it-py, with myst-parser)")

import docblocks  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BLOCKS = [b for page in docblocks.pages(ROOT) for b in docblocks.blocks(page)]
TOTAL: dict[str, float] = {}  # page -> s from the start to its last block's end
SECONDS: dict[str, float] = {}  # block -> s it ran


def _children_cpu() -> float:
    """CPU s (user + system) of this process's ended and waited-for children (and theirs)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def budget(page_blocks: list) -> float:
    """What a page's blocks may take (s), the sum of their budgets: the pages that may take longest
    start first, so that no long page is left to run alone at the end (the order of the pages
    is no part of what they check: each has a scratch folder and a shell of its own)."""
    return sum(block.timeout for block in page_blocks if block.file is None)


@pytest.fixture(scope="module")
def outcomes(venv, tmp_path_factory, request):
    """Each selected block's Outcome as a Future: the pages two at a time, the ones with the largest
    budget first (budget), a page's blocks in order."""
    selected = {item.callspec.params["block"] for item in request.session.items
                if item.module is request.module and hasattr(item, "callspec")
                and "block" in item.callspec.params}
    futures: dict[docblocks.Block, Future] = {b: Future() for b in BLOCKS if b in selected}
    by_page: dict[Path, list] = {}
    for block in futures:
        by_page.setdefault(block.page, []).append(block)
    env = dict(venv.env)
    start, cpu = time.monotonic(), _children_cpu()

    def follow(page: Path, page_blocks: list) -> None:
        scratch = tmp_path_factory.mktemp(page.stem)
        state = tmp_path_factory.mktemp("shell") / "state.sh"
        for block in page_blocks:
            try:
                outcome = docblocks.run_block(block, env, scratch, str(venv.bin / "python"), state)
                SECONDS[block.where(ROOT)] = outcome.seconds
                futures[block].set_result(outcome)
            except Exception as error:  # noqa: BLE001 (the test reports it)
                futures[block].set_exception(error)
        TOTAL[str(page.relative_to(ROOT))] = time.monotonic() - start

    pool = ThreadPoolExecutor(max_workers=2)
    for page, page_blocks in sorted(by_page.items(), key=lambda item: -budget(item[1])):
        pool.submit(follow, page, page_blocks)
    yield futures
    pool.shutdown(wait=True, cancel_futures=True)
    if TOTAL:
        own = {str(page.relative_to(ROOT)): sum(SECONDS.get(b.where(ROOT), 0.0) for b in blocks)
               for page, blocks in by_page.items()}
        print(f"\ndocs blocks: {len(futures)} in {time.monotonic() - start:.1f} s (their processes' "
              f"CPU {_children_cpu() - cpu:.0f} s); pages (s run, "
              "s from the start to done) " + ", ".join(f"{page} {own[page]:.0f}/{s:.0f}" for page, s
                                                     in sorted(TOTAL.items(), key=lambda i: i[1]))
              + "; slowest blocks " + ", ".join(f"{where} {s:.1f}" for where, s in
                                                sorted(SECONDS.items(), key=lambda i: -i[1])[:12]))


@pytest.mark.slow
@pytest.mark.parametrize("block", BLOCKS, ids=[b.where(ROOT) for b in BLOCKS])
def test_documented_block_runs(outcomes, block):
    outcome = outcomes[block].result(timeout=block.timeout + 120)
    if outcome.skipped:
        pytest.skip(f"{block.where(ROOT)}: {outcome.skipped}")
    assert outcome.problem is None, docblocks.report(outcome, ROOT)


def test_the_harness_finds_every_page_and_block():
    """README.md and every docs page, other helpers' too; the generated pages are not sources."""
    pages = docblocks.pages(ROOT)
    assert pages[0] == ROOT / "README.md"
    assert ROOT / "docs" / "contributing.md" in pages
    assert not [p for p in pages if "_generated" in p.parts or "_build" in p.parts]
    assert any(b.page == ROOT / "README.md" for b in BLOCKS)


def test_a_stale_page_fails_the_harness(tmp_path):
    """The fixture page's stale command, stale import, wrong figure and slow block each fail,
    naming the page and line; its text and console blocks are not run; a good block passes."""
    page = ROOT / "tests" / "data" / "docs" / "stale.md"
    found = docblocks.blocks(page)
    assert [(b.lang, b.line) for b in found] == [("bash", 5), ("python", 11), ("bash", 18),
                                                 ("bash", 25), ("bash", 41), ("bash", 46)]
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    state = tmp_path / "state.sh"
    results = [docblocks.run_block(b, env, tmp_path, sys.executable, state) for b in found]
    problems = [r.problem for r in results]
    assert problems[0] == "exit 2" and "--no-such-option" in results[0].output
    assert problems[1] == "exit 1" and "LabThatWasRenamed" in results[1].output
    assert problems[2] == "its output does not say 'pelvis at 9.999 m'"
    assert problems[3] == "still running after its budget of 1 s" and results[3].seconds < 10
    assert problems[4] is None and (tmp_path / "there" / "here.txt").is_file()
    assert results[5].problem is None and "carried" in results[5].output  # its cd and export
    assert docblocks.report(results[0], ROOT).startswith("tests/data/docs/stale.md:5: ```bash block: exit 2")


def test_a_misspelt_marker_is_an_error(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("<!-- need: ros1 -->\n```bash\ntrue\n```\n")
    with pytest.raises(ValueError, match="page.md:1: unknown block marker 'need: ros1'"):
        docblocks.blocks(page)
    page.write_text("<!-- needs: ros3 -->\n```bash\ntrue\n```\n")
    with pytest.raises(ValueError, match="unknown need"):
        docblocks.blocks(page)
    page.write_text("<!-- the robot, as drawn above -->\n```bash\ntrue\n```\n")  # prose: no marker
    assert docblocks.blocks(page)[0].needs == frozenset()


def test_a_display_block_gets_a_virtual_display(tmp_path):
    """`needs: display` runs the block under Xvfb (its DISPLAY is set; without the marker none is)."""
    page = tmp_path / "page.md"
    page.write_text("<!-- needs: display -->\n```bash\nxdpyinfo >/dev/null || test -n \"$DISPLAY\"\n"
                    "echo \"display $DISPLAY\"\n```\n\n```bash\necho \"display [${DISPLAY:-}]\"\n```\n")
    shown, plain = docblocks.blocks(page)
    env = dict(os.environ, DISPLAY=":99")  # a display of the test's own is not passed on
    outcome = docblocks.run_block(shown, env, tmp_path)
    if outcome.skipped:
        pytest.skip(outcome.skipped)
    assert outcome.problem is None and "display :" in outcome.output
    assert "display []" in docblocks.run_block(plain, env, tmp_path).output


def test_an_install_from_a_package_index_is_refused(tmp_path):
    """mexone is on no package index: `pip install 'mexone[ros2]'` (prose or block) fails the
    page, and so does an extra pyproject.toml lacks; `pip install ".[ros2]"` passes."""
    (tmp_path / "pyproject.toml").write_text('[project]\nname = "x"\n'
                                             '[project.optional-dependencies]\nros2 = []\n')
    page = tmp_path / "page.md"
    for bad, said in (("Then `pip install 'mexone[ros2]'`.", "asks a package index"),
                      ('```console\n$ pip install "mexone[ros2]"\n```', "asks a package index"),
                      ("```text\npip install mexone\n```", "asks a package index"),
                      ('Run `pip install ".[ros3]"`.', "no extra ros3")):
        page.write_text(f"# A page\n\n{bad}\n")
        with pytest.raises(ValueError, match=f"page.md:[34]: .*{said}"):
            docblocks.blocks(page)
    page.write_text('Run `pip install ".[ros2]"`, then `pip install -e ".[ros2]"`.\n')
    assert docblocks.blocks(page) == []


def test_no_message_asks_a_package_index_for_mexone():
    """The hints a user reads (a missing extra) name the form that works from a clone, too."""
    pattern = re.compile(r"pip3? install\W+mexone\b")
    said = [f"{path.relative_to(ROOT)}: {line.strip()}"
            for path in (ROOT / "src" / "mexone").rglob("*.py")
            for line in path.read_text().splitlines() if pattern.search(line)]
    assert not said, said


def test_a_command_that_needs_an_extra_is_shown_with_it():
    """Where a page shows `python -m mexone.ros2.interfaces`, the same paragraph or block names
    the ros2-build extra it needs (ament_package, the rosidl tools)."""
    for page in docblocks.pages(ROOT):
        for paragraph in re.split(r"\n\s*\n", page.read_text()):
            if "mexone.ros2.interfaces" in paragraph and "DECISIONS" not in page.name:
                assert "ros2-build" in paragraph, f"{page.relative_to(ROOT)}: {paragraph[:300]}"


def test_output_the_page_shows_must_appear(tmp_path):
    """`<!-- output -->` before a shown block: each of its lines is a line the run above printed
    (`...`: any text), else the block fails naming the line; a marker in the wrong place is
    an error."""
    page = tmp_path / "page.md"
    page.write_text("```bash\necho 'mexone: ready on port 41234'; echo '  second  '\n```\n\n"
                    "It prints:\n\n<!-- output -->\n```text\nmexone: ready on port ...\nsecond\n"
                    "```\n\n```bash\necho 'mexone: ready'\n```\n\n<!-- output -->\n```text\n"
                    "mexone: ready\nmexone: never printed\n```\n")
    good, bad = docblocks.blocks(page)
    assert good.output == ((9, "mexone: ready on port ..."), (10, "second"))
    assert docblocks.run_block(good, dict(os.environ), tmp_path).problem is None
    outcome = docblocks.run_block(bad, dict(os.environ), tmp_path)
    assert outcome.problem == "its output has no line 'mexone: never printed' (line 20 shows it as the output)"
    for wrong, said in (("<!-- output -->\n```bash\ntrue\n```\n", "not before a run block"),
                        ("# Title\n\n<!-- output -->\n```text\nx\n```\n", "no run block before it"),
                        ("<!-- timeout: 5 -->\n```text\nx\n```\n", "is not run")):
        page.write_text(wrong)
        with pytest.raises(ValueError, match=said):
            docblocks.blocks(page)


def test_a_ros2_block_runs_as_after_pip_install_ros2(tmp_path):
    """`needs: ros2`: rclpy imports, and the message packages `python -m mexone.ros2.interfaces`
    builds do not (hidden, as before that step), whatever MEXONE_ROS2_PYTHON's venv holds."""
    page = tmp_path / "page.md"
    page.write_text("<!-- needs: ros2 -->\n```bash\npython -c 'import rclpy, std_msgs.msg'\n"
                    "python -c 'import tf2_msgs' || echo \"no tf2_msgs\"\n"
                    "mexone --help >/dev/null && echo \"domain $ROS_DOMAIN_ID\"\n```\n")
    (block,) = docblocks.blocks(page)
    outcome = docblocks.run_block(block, dict(os.environ), tmp_path, sys.executable)
    if outcome.skipped:
        pytest.skip(outcome.skipped)
    assert outcome.problem is None, docblocks.report(outcome, tmp_path)
    assert "No module named 'tf2_msgs'" in outcome.output and "no tf2_msgs" in outcome.output
    assert f"domain {101 + os.getpid() % 100}" in outcome.output  # not the ROS 2 tests' domain


def _first_column(table_head: str) -> set[str]:
    """The `names` in the first column of the README's table that follows `table_head`."""
    text = (ROOT / "README.md").read_text()
    rows = text[text.index(table_head):].split("\n\n")[0].splitlines()
    return {name for row in rows if row.startswith("| `")
            for name in re.findall(r"`([^`]+)`", row.split("|")[1])}


def test_the_readme_names_every_extra_and_verb():
    """The README's tables of extras and verbs hold every extra pyproject.toml declares and
    every verb `mexone --help` lists (example-robot, exercise and four extras were missing)."""
    import tomllib

    from mexone.cli import build_parser

    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert _first_column("| extra |") == set(extras)
    verbs = next(a for a in build_parser()._actions if a.dest == "verb").choices
    assert _first_column("| verb |") == set(verbs)


def test_a_file_block_of_any_kind_is_saved(tmp_path):
    """`<!-- file: NAME -->` saves a YAML as it saves a routine (the YAML's marker was ignored,
    and the block after it found no file)."""
    page = tmp_path / "page.md"
    page.write_text("<!-- file: c.yaml -->\n```yaml\nmex_rb: {}\n```\n\n```bash\ncat c.yaml\n```\n")
    saved, shown = docblocks.blocks(page)
    assert (saved.lang, saved.file) == ("yaml", "c.yaml")
    for block in (saved, shown):
        outcome = docblocks.run_block(block, dict(os.environ), tmp_path)
        assert outcome.problem is None, docblocks.report(outcome, tmp_path)
    assert "mex_rb: {}" in outcome.output
