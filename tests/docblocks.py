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
    needs: ros2     `mexone` and `python` are MEXONE_ROS2_PYTHON's (PyPI's ROS 2 wheels) with
                    the wheel under test first on its path and the message packages
                    `python -m mexone.ros2.interfaces` builds hidden: a reader's venv right
                    after `pip install ".[ros2]"`; DDS on this machine, in a domain of its own
    timeout: S      the block's budget in seconds
    expect: TEXT    its output must contain TEXT (a figure the page states, checked)
    serves: PORT    a server: it passes once http://127.0.0.1:PORT answers, then gets Ctrl-C
    file: NAME      not run: the block (of any kind: python, yaml, ...) is written to NAME,
                    for the next blocks (a routine, a controllers YAML)
- `<!-- output -->` before a block that is shown, not run (```text): it shows what the last
  run block above it prints, and each of its lines must be a line of that run's output
  (`...` stands for any text: a port, a time); a promised message that never appears fails;
- a page must not tell a reader to `pip install mexone` or `'mexone[extra]'` (mexone is on no
  package index: `pip install ".[extra]"` from a clone), nor name an extra pyproject.toml lacks.
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
NEEDS = ("ros1", "display", "ros2")
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
    output: tuple[tuple[int, str], ...] = ()  # (page line, text) of what the page says it prints

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
    """A marker comment's options; a comment that is prose (no leading `word:`, and not
    `output`) marks nothing."""
    body = comment.strip().removeprefix("<!--").removesuffix("-->").strip()
    options: dict = {}
    if body == "output":
        return {"output": True}
    if not re.match(r"[a-z_]+\s*:", body):
        return options
    for item in filter(None, (part.strip() for part in body.split(";"))):
        key, sep, value = item.partition(":")
        key, value = key.strip(), value.strip()
        if not sep or key not in ("needs", "timeout", "expect", "serves", "file"):
            raise ValueError(f"{where}: unknown block marker '{item}' "
                             "(needs, timeout, expect, serves, file; or output alone)")
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
    """The ```bash and ```python blocks of a Markdown page and those it saves to a file (`file:`),
    with their markers and the output
    the page shows for them (`<!-- output -->`). A page that tells a reader to install mexone
    from a package index, a misspelt marker or an output block with no run before it is a
    ValueError naming the page and line."""
    from markdown_it import MarkdownIt

    text = page.read_text()
    check_installs(page, text)
    tokens = MarkdownIt("commonmark").parse(text)
    found: list[dict] = []
    for i, token in enumerate(tokens):
        if token.type != "fence":
            continue
        lang = token.info.split()[0] if token.info else ""
        line = token.map[0] + 1
        before = tokens[i - 1] if i else None
        options = {}
        if (before is not None and before.type == "html_block"
                and before.content.lstrip().startswith("<!--") and before.map[1] >= token.map[0] - 1):
            options = _options(before.content, f"{page}:{before.map[0] + 1}")
        if options.pop("output", False):
            if lang in RUN:
                raise ValueError(f"{page}:{line}: an output marker goes before the block that "
                                 "shows a run's output (```text), not before a run block")
            if not found or found[-1].get("file"):
                raise ValueError(f"{page}:{line}: output shown with no run block before it")
            shown = tuple((line + 1 + k, text.strip()) for k, text in
                          enumerate(token.content.splitlines()) if text.strip())
            found[-1]["output"] = found[-1].get("output", ()) + shown
        elif lang in RUN or options.get("file"):  # a file of any kind: a YAML, a routine
            found.append(dict(page=page, line=line, lang=lang, code=token.content, **options))
        elif options:
            raise ValueError(f"{page}:{line}: a ```{lang or 'plain'} block is not run: its "
                             "marker does nothing (bash and python blocks run; file: saves any)")
    return [Block(**kwargs) for kwargs in found]


_INSTALL = re.compile(r"pip3? install ([^`\n#();&|]*)")  # its arguments: to a comment, `, ( ...


def check_installs(page: Path, text: str) -> None:
    """Every `pip install` on the page works from a clone: no `mexone` or `'mexone[extra]'`
    (that asks a package index for mexone, which is on none), and every extra of `".[extra]"`
    is one pyproject.toml declares."""
    project = next((p / "pyproject.toml" for p in page.resolve().parents
                    if (p / "pyproject.toml").is_file()), None)
    extras = None
    if project is not None:
        import tomllib

        extras = set(tomllib.loads(project.read_text())["project"].get("optional-dependencies", {}))
    for match in _INSTALL.finditer(text):
        line = text.count("\n", 0, match.start()) + 1
        for arg in match.group(1).split():
            arg = arg.strip("'\"")
            if re.match(r"mexone(\W|$)", arg):
                raise ValueError(f"{page}:{line}: `pip install {arg}` asks a package index for "
                                 "mexone, which is on none: write pip install \".[extra]\" "
                                 "(from a clone)")
            wanted = re.fullmatch(r"\.\[([\w,-]+)\]", arg)
            unknown = set(wanted.group(1).split(",")) - extras if wanted and extras else set()
            if unknown:
                raise ValueError(f"{page}:{line}: `pip install {arg}`: pyproject.toml has no "
                                 f"extra {', '.join(sorted(unknown))} (it has: "
                                 f"{', '.join(sorted(extras))})")


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


def hide_modules(folder: Path, names) -> Path:
    """A sitecustomize.py in `folder` that makes the top-level packages `names` unimportable
    (ModuleNotFoundError, as if never installed): `folder` first on PYTHONPATH shows a Python
    without them, and nothing installed is touched."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "sitecustomize.py").write_text(
        '"""Written by the docs harness (tests/docblocks.py): these packages are hidden."""\n'
        "import sys\n\n"
        f"HIDDEN = {sorted(names)!r}\n\n\n"
        "class _Hidden:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name.partition('.')[0] in HIDDEN:\n"
        "            raise ModuleNotFoundError(f'No module named {name!r}', name=name)\n"
        "        return None\n\n\n"
        "sys.meta_path.insert(0, _Hidden())\n")
    return folder


def ros2_python(env: dict) -> str | None:
    """MEXONE_ROS2_PYTHON when it is a Python with rclpy (PyPI's ROS 2 wheels), else None."""
    candidate = env.get("MEXONE_ROS2_PYTHON")
    if not candidate or not Path(candidate).exists():
        return None
    clean = {k: v for k, v in env.items() if k != "PYTHONPATH"}
    ok = subprocess.run([candidate, "-c", "import rclpy"], env=clean, capture_output=True,
                        timeout=60).returncode == 0
    return candidate if ok else None


def _ros2_reader(env: dict, python: str, tmp: Path) -> dict:
    """`needs: ros2`: the environment of a reader who ran `pip install ".[ros2]"` (the wheel
    under test, PyPI's ROS 2 wheels, not yet the packages mexone.ros2.interfaces builds)."""
    from mexone.ros2.interfaces import PACKAGES

    ros2 = env["MEXONE_ROS2_PYTHON"]
    wheel_site = subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                capture_output=True, text=True, timeout=60, env=env).stdout.strip()
    bin_dir = tmp / "ros2-bin"
    bin_dir.mkdir()
    for name, run in (("mexone", f'"{ros2}" -m mexone'), ("python", f'"{ros2}"'),
                      ("python3", f'"{ros2}"')):
        (bin_dir / name).write_text(f'#!/bin/sh\nexec {run} "$@"\n')
        (bin_dir / name).chmod(0o755)
    hidden = hide_modules(tmp / "ros2-hidden", PACKAGES)
    # ROS 1's variables stay out (its genpy packages shadow ROS 2's); DDS stays on this machine
    env = {k: v for k, v in env.items() if not k.startswith("ROS_")}
    return env | {"PATH": f"{bin_dir}{os.pathsep}{env.get('PATH', '')}",
                  "PYTHONPATH": f"{hidden}{os.pathsep}{wheel_site}",
                  "ROS_DOMAIN_ID": str(101 + os.getpid() % 100),
                  "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_LOCALHOST_ONLY": "1"}


def run_block(block: Block, env: dict, cwd: Path, python: str = "python3",
              state: Path | None = None) -> Outcome:
    """Run one block in `cwd` with `env` (its PATH finds the `mexone` under test). `state`: a
    file holding the shell's folder and exports, read before the block and written after it."""
    for need, tool in (("ros1", "roscore"), ("display", "xvfb-run")):
        if need in block.needs and shutil.which(tool, path=env.get("PATH")) is None:
            return Outcome(block, None, "", 0.0, skipped=f"needs {need}: {tool} is not installed")
    if "ros2" in block.needs and ros2_python(env) is None:
        return Outcome(block, None, "", 0.0, skipped="needs ros2: MEXONE_ROS2_PYTHON names no "
                       "Python with PyPI's ROS 2 wheels (scripts/test.sh makes .venv-ros2)")
    env = {k: v for k, v in env.items() if k != "DISPLAY"} | {"MPLBACKEND": "Agg"}
    with tempfile.TemporaryDirectory() as tmp:
        if "ros2" in block.needs:
            env = _ros2_reader(env, python, Path(tmp))
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
    lines = [line.strip() for line in output.splitlines()]
    for where, text in block.output:
        shown = re.compile(".*?".join(re.escape(part) for part in text.split("...")))
        if outcome.problem is None and not any(shown.fullmatch(line) for line in lines):
            outcome.problem = (f"its output has no line '{text}' (line {where} shows it as the "
                               "output)")
    return outcome


def report(outcome: Outcome, root: Path) -> str:
    """What failed, where, and the end of what it printed: for an assertion message."""
    block = outcome.block
    return (f"{block.where(root)}: ```{block.lang} block: {outcome.problem} after "
            f"{outcome.seconds:.1f} s\n{block.code}--- its output (end) ---\n{outcome.output[-3000:]}")
