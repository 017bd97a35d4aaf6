"""The code blocks of README.md and docs/**/*.md, and how tests/test_docs_commands.py runs them.

The convention (docs/contributing.md says the same for writers):
- a ```bash block is run by bash (`-e -o pipefail`), a ```python block by the venv's python;
  ```text, ```console and every other kind are shown, never run;
- the blocks of one page run in order, as one reader's terminal: they start in a scratch
  folder, and a bash block's `cd` and `export`s carry over to the page's next blocks; each has
  a time budget (60 s unless its marker says);
- an HTML comment on the line(s) before a block marks what it needs, `;`-separated:
  `<!-- needs: ros1 display; timeout: 120; expect: stayed standing; serves: 8080 -->`
    needs: ros1     a roscore is started for the block (on a free port) and
                    `eval "$(mexone ros-env)"` runs first, as a reader's ~/.bashrc has it
    needs: display  the block runs under a virtual X server (`xvfb-run -a`)
    timeout: S      the block's budget in seconds
    expect: TEXT    its output must contain TEXT (a figure the page states, checked)
    serves: PORT    a server: it passes once http://127.0.0.1:PORT answers, then gets Ctrl-C
    file: NAME      not run: the block is written to NAME (a routine the next block runs)
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import socket
import subprocess
import tempfile
import threading
import time
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["Block", "Outcome", "blocks", "run_block", "pages", "report"]

RUN = ("bash", "python")
NEEDS = ("ros1", "display")
DEFAULT_TIMEOUT = 60.0
_SERVING = threading.Lock()  # one server at a time: two pages may both serve on 8080


@dataclass(frozen=True)
class Block:
    page: Path
    line: int  # of the opening fence, 1-based
    lang: str
    code: str
    needs: frozenset[str] = frozenset()
    timeout: float = DEFAULT_TIMEOUT
    expect: tuple[str, ...] = ()
    serves: int | None = None
    file: str | None = None

    def where(self, root: Path) -> str:
        page = self.page.relative_to(root) if self.page.is_relative_to(root) else self.page
        return f"{page}:{self.line}"


@dataclass
class Outcome:
    block: Block
    returncode: int | None
    output: str
    seconds: float
    problem: str | None = None  # None: it did what the page says
    skipped: str | None = None
    notes: list[str] = field(default_factory=list)


def pages(root: Path) -> list[Path]:
    """README.md and every page under docs/ (not the generated or built ones: docs/_*)."""
    docs = root / "docs"
    found = [p for p in docs.rglob("*.md")
             if not any(part.startswith(("_", ".")) for part in p.relative_to(docs).parts)]
    return [root / "README.md", *sorted(found)]


def _options(comment: str, where: str) -> dict:
    """A marker comment's options; a comment that is prose (no leading `word:`) marks nothing."""
    body = comment.strip().removeprefix("<!--").removesuffix("-->").strip()
    options: dict = {}
    if not re.match(r"[a-z_]+\s*:", body):
        return options
    for item in filter(None, (part.strip() for part in body.split(";"))):
        key, sep, value = item.partition(":")
        key, value = key.strip(), value.strip()
        if not sep or key not in ("needs", "timeout", "expect", "serves", "file"):
            raise ValueError(f"{where}: unknown block marker '{item}' "
                             "(needs, timeout, expect, serves, file)")
        if key == "needs":
            unknown = set(value.split()) - set(NEEDS)
            if unknown:
                raise ValueError(f"{where}: unknown need {sorted(unknown)} (known: {', '.join(NEEDS)})")
            options["needs"] = frozenset(value.split())
        elif key == "timeout":
            options["timeout"] = float(value)
        elif key == "serves":
            options["serves"] = int(value)
        elif key == "file":
            options["file"] = value
        else:
            options["expect"] = (*options.get("expect", ()), value)
    return options


def blocks(page: Path) -> list[Block]:
    """The ```bash and ```python blocks of a Markdown page, with their markers."""
    from markdown_it import MarkdownIt

    tokens = MarkdownIt("commonmark").parse(page.read_text())
    found = []
    for i, token in enumerate(tokens):
        lang = token.info.split()[0] if token.type == "fence" and token.info else ""
        if lang not in RUN:
            continue
        line = token.map[0] + 1
        before = tokens[i - 1] if i else None
        options = {}
        if (before is not None and before.type == "html_block"
                and before.content.lstrip().startswith("<!--") and before.map[1] >= token.map[0] - 1):
            options = _options(before.content, f"{page}:{before.map[0] + 1}")
        found.append(Block(page, line, lang, token.content, **options))
    return found


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _stop(process: subprocess.Popen, sig: int = signal.SIGKILL) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.killpg(process.pid, sig)


def _answers(port: int) -> bool:
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=1) as response:
            return response.status == 200
    except OSError:
        return False


def _roscore(env: dict, scratch: Path) -> tuple[subprocess.Popen, dict]:
    port = _free_port()
    env = dict(env, ROS_MASTER_URI=f"http://127.0.0.1:{port}", ROS_HOSTNAME="127.0.0.1",
               ROS_LOG_DIR=str(scratch / ".ros_log"))
    core = subprocess.Popen(["roscore", "-p", str(port)], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    end = time.monotonic() + 30
    while time.monotonic() < end and core.poll() is None:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                break
        time.sleep(0.1)  # polling a port that is not open yet: nothing to wait on
    return core, env


def run_block(block: Block, env: dict, cwd: Path, python: str = "python3",
              state: Path | None = None) -> Outcome:
    """Run one block in `cwd` with `env` (its PATH finds the `mexone` under test). `state`: a
    file holding the shell's folder and exports, read before the block and written after it."""
    for need, tool in (("ros1", "roscore"), ("display", "xvfb-run")):
        if need in block.needs and shutil.which(tool, path=env.get("PATH")) is None:
            return Outcome(block, None, "", 0.0, skipped=f"needs {need}: {tool} is not installed")
    env = {k: v for k, v in env.items() if k != "DISPLAY"} | {"MPLBACKEND": "Agg"}
    with tempfile.TemporaryDirectory() as tmp:
        script = block.code
        if block.file:
            script = f"cat > '{block.file}' <<'MEXONE_DOCS_EOF'\n{block.code}MEXONE_DOCS_EOF\n"
        elif block.lang == "python":
            source = Path(tmp) / "block.py"
            source.write_text(block.code)
            script = f'exec {python} "{source}"\n'
        if "ros1" in block.needs:
            script = 'eval "$(mexone ros-env)"\n' + script
        if state is not None:
            script = (f'[ -f "{state}" ] && source "{state}"\n{script}\n'
                      f'{{ export -p; echo "cd $(printf %q "$PWD")"; }} > "{state}"\n')
        command = ["bash", "-e", "-o", "pipefail", "-c", script]
        if "display" in block.needs:
            command = ["xvfb-run", "-a", *command]
        core = None
        if "ros1" in block.needs:
            core, env = _roscore(env, Path(tmp))
        lock = _SERVING if block.serves else None
        if lock:
            lock.acquire()
        start = time.monotonic()
        process = subprocess.Popen(command, cwd=cwd, env=env, stdout=subprocess.PIPE,
                                   stderr=subprocess.STDOUT, text=True, start_new_session=True)
        try:
            return _finish(block, process, start)
        finally:
            _stop(process)
            if lock:
                lock.release()
            if core is not None:
                _stop(core, signal.SIGINT)
                try:
                    core.wait(timeout=15)
                except subprocess.TimeoutExpired:
                    _stop(core)


def _finish(block: Block, process: subprocess.Popen, start: float) -> Outcome:
    served = False
    if block.serves:
        end = start + block.timeout
        while time.monotonic() < end and process.poll() is None and not served:
            served = _answers(block.serves)
            if not served:
                time.sleep(0.2)  # a server coming up: poll its port
        _stop(process, signal.SIGINT)
    try:
        output, _ = process.communicate(timeout=block.timeout if not block.serves else 20)
    except subprocess.TimeoutExpired:
        _stop(process)
        output, _ = process.communicate()
        seconds = time.monotonic() - start
        return Outcome(block, None, output, seconds,
                       problem=f"still running after its budget of {block.timeout:g} s")
    seconds = time.monotonic() - start
    outcome = Outcome(block, process.returncode, output, seconds)
    if block.serves:
        if not served:
            outcome.problem = (f"never answered on http://127.0.0.1:{block.serves}/ "
                               f"(exit {process.returncode})")
    elif process.returncode != 0:
        outcome.problem = f"exit {process.returncode}"
    for text in block.expect:
        if outcome.problem is None and text not in output:
            outcome.problem = f"its output does not say '{text}'"
    return outcome


def report(outcome: Outcome, root: Path) -> str:
    """What failed, where, and the end of what it printed: for an assertion message."""
    block = outcome.block
    return (f"{block.where(root)}: ```{block.lang} block: {outcome.problem} after "
            f"{outcome.seconds:.1f} s\n{block.code}--- its output (end) ---\n{outcome.output[-3000:]}")
