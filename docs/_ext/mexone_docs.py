"""The pages Sphinx builds from the code instead of from git (all under docs/_generated/, and
docs/ranges.md; none of them is committed):

- `_generated/cli.md`: every `mexone` verb's `--help`, from the parser `mexone` itself runs;
- `_generated/api/*.md`: an `automodule` per public module (`mexone.API`), each object of its
  `__all__` documented once, where users import it from (the shallowest module that exports it);
- `ranges.md`: `python -m mexone.ranges`'s table (`mexone.ranges.docs_page`);
- `_generated/gallery.md`: each numbered example run into a scratch folder, with what it
  prints and the picture it draws (cached by a hash of the example and of mexone's source);
- `_generated/layout.md`: the layers, from tests/test_layers.py (docs/contributing.md includes
  it);
- `_generated/more.md`: a table of contents of the topic pages at docs/*.md that no section
  lists by name (so a new page is on the site as soon as it is in docs/).
"""

from __future__ import annotations

import hashlib
import importlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from sphinx.application import Sphinx
from sphinx.errors import ExtensionError

__all__ = ["public_modules", "setup"]

# pages the hand-written sections list by name: not repeated under "More guides"
LISTED = {"index", "DECISIONS", "ranges"}


def public_modules() -> list:
    """The public API's modules (`mexone.API`: what a student, a teacher and a plug-in author
    import), shallowest first; every other module is internal and has no reference page."""
    import mexone

    names = {name for modules in mexone.API.values() for name in modules}
    found = [importlib.import_module(name) for name in names]
    return sorted(found, key=lambda m: (m.__name__.count("."), m.__name__))


def _identity(value) -> int | None:
    """What makes two exported names one object (numbers and strings are not objects here)."""
    if value is None or isinstance(value, int | float | str | bytes | bool | tuple | frozenset):
        return None
    return id(value)


def _docstring(module) -> list[str]:
    import inspect

    return (inspect.getdoc(module) or "").splitlines()


def _directive(value) -> str:
    import inspect

    if inspect.isclass(value):
        return "autoexception" if issubclass(value, BaseException) else "autoclass"
    return "autofunction" if inspect.isroutine(value) else "autodata"


def _api_pages(out: Path) -> None:
    modules = public_modules()
    seen: dict[int, str] = {}
    groups: dict[str, list[str]] = {}
    for module in modules:
        name = module.__name__
        parts = name.split(".")
        group = "mexone" if len(parts) == 1 or (len(parts) == 2 and not hasattr(module, "__path__")) \
            else ".".join(parts[:2])
        excluded, elsewhere, lazy = [], [], []
        for member in module.__all__:
            value = getattr(module, member, None)
            key = _identity(value)
            if _directive(value) != "autodata" and getattr(value, "__name__", member) != member:
                # an alias under another name (`mexone.Controller`): named here as an alias,
                # documented where it is defined under its own name
                lazy.append(member)
            elif member not in vars(module):  # a module __getattr__'s: automodule cannot see it
                excluded.append(member)
                elsewhere.append(f"`{member}` ({{py:obj}}`{value.__module__}.{member}`)")
            elif key is not None and key in seen:
                excluded.append(member)
                elsewhere.append(f"`{member}` ({{py:obj}}`{seen[key]}.{member}`)")
            elif key is not None:
                seen[key] = name
        block = [f"## `{name}`", "", "```{eval-rst}"]
        parent, _, leaf = name.rpartition(".")
        shadowed = getattr(sys.modules.get(parent), leaf, module) is not module
        if shadowed:  # `mexone.motion.walk` is a function there: document the module's members
            block += [f".. currentmodule:: {name}", "", *_docstring(module), ""]
            for member in module.__all__:
                if member not in excluded:
                    kind = _directive(getattr(module, member))
                    block += [f".. {kind}:: {member}", *(["   :no-value:"] if kind == "autodata" else []), ""]
        else:
            # data (constants, tables) is listed by name after the module's classes and functions:
            # autodoc skips a module attribute without a `#:` comment even with undoc-members
            data = [m for m in module.__all__ if m not in excluded and m not in lazy
                    and _directive(getattr(module, m, None)) == "autodata"]
            block.append(f".. automodule:: {name}")
            if excluded or data or lazy:
                block.append(f"   :exclude-members: {', '.join(excluded + data + lazy)}")
            block.append("")
            for member in data:
                block += [f".. autodata:: {name}.{member}", "   :no-value:", ""]
            for member in lazy:
                value = getattr(module, member)
                kind = "class" if _directive(value) in ("autoclass", "autoexception") else \
                    "function" if _directive(value) == "autofunction" else "data"
                target = f"{value.__module__}.{value.__qualname__}"
                block += [f".. py:{kind}:: {member}", f"   :module: {name}", "",
                          f"   An alias of :py:obj:`{target}`.", ""]
        block += ["```", ""]
        if elsewhere:
            block += ["Also exported here: " + ", ".join(elsewhere) + ".", ""]
        groups.setdefault(group, []).extend(block)
    (out / "api").mkdir(parents=True, exist_ok=True)
    index = ["# Python API, module by module", "",
             "Every name of the public API (`mexone.API`), from its docstring. A class or function",
             "exported by several modules is documented once, where you import it from.", "",
             "```{toctree}", ":maxdepth: 1", ""]
    for group, lines in groups.items():
        title = f"# `{group}`" if group != "mexone" else "# `mexone` (top-level modules)"
        (out / "api" / f"{group}.md").write_text("\n".join([title, "", *lines]))
        index.append(f"{group}")
    index += ["```", ""]
    (out / "api" / "index.md").write_text("\n".join(index))


def _cli_page(out: Path) -> None:
    os.environ["COLUMNS"] = "100"  # argparse wraps to the terminal: the same page everywhere
    from mexone.cli import build_parser

    parser = build_parser()
    (verbs,) = [a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction"]
    helps = {a.dest: a.help for a in verbs._choices_actions}
    lines = ["# Command line", "",
             "Every verb of `mexone`, as its `--help` prints it (this page is generated from the",
             "parser `mexone` runs). Exit codes: 0 ok, 1 findings or failed checks, 2 bad input",
             "(one line on stderr), 130 / 143 stopped by Ctrl-C / SIGTERM.", "",
             "```text", parser.format_help().rstrip(), "```", ""]
    for verb, sub in verbs.choices.items():
        lines += [f"(cli-{verb})=", f"## `mexone {verb}`", ""]
        if helps.get(verb):
            lines += [helps[verb][0].upper() + helps[verb][1:] + ".", ""]
        lines += ["```text", sub.format_help().rstrip(), "```", ""]
    (out / "cli.md").write_text("\n".join(lines))


def _source_hash(root: Path, example: Path) -> str:
    digest = hashlib.sha256(example.read_bytes())
    src = root / "src" / "mexone"
    for path in sorted(src.rglob("*")) if src.is_dir() else []:
        if path.is_file() and path.suffix in (".py", ".yaml", ".urdf", ".xacro", ".xml"):
            digest.update(path.relative_to(src).as_posix().encode() + path.read_bytes())
    return digest.hexdigest()[:16]


def _run_example(root: Path, example: Path, cache: Path) -> dict:
    """Run one example into a scratch folder; its stdout and pictures, cached."""
    key = _source_hash(root, example)
    folder = cache / example.stem
    record = folder / "run.json"
    if record.is_file() and json.loads(record.read_text()).get("key") == key:
        return json.loads(record.read_text())
    env = dict(os.environ, MPLBACKEND="Agg")
    if (root / "src" / "mexone").is_dir():
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(root / "src"), env.get("PYTHONPATH")]))
    with tempfile.TemporaryDirectory() as scratch:
        out = subprocess.run([sys.executable, str(example), scratch], cwd=scratch, env=env,
                             capture_output=True, text=True, timeout=600)
        if out.returncode != 0:
            raise ExtensionError(f"examples/{example.name} failed (exit {out.returncode}): "
                                 f"{out.stderr.strip().splitlines()[-1:]}")
        pictures = sorted(Path(scratch).glob("*.png"))
        if not pictures:
            raise ExtensionError(f"examples/{example.name} drew no picture (a .png in its out_dir)")
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir(parents=True)
        for picture in pictures:
            shutil.copy(picture, folder / picture.name)
    stdout = "\n".join(line.replace(scratch, "OUT") for line in out.stdout.strip().splitlines())
    result = {"key": key, "stdout": stdout, "pictures": [p.name for p in pictures]}
    record.write_text(json.dumps(result))
    return result


def _gallery_page(root: Path, out: Path) -> None:
    examples = sorted((root / "examples").glob("[0-9][0-9]_*.py"))
    cache = out / "gallery"
    with ThreadPoolExecutor(max_workers=2) as pool:
        runs = list(pool.map(lambda e: _run_example(root, e, cache), examples))
    lines = ["# Example gallery", "",
             "The numbered examples in the repository's `examples/` folder, each run when these",
             "pages were built: what it prints, and the picture it draws into its `out_dir`.", ""]
    for example, run in zip(examples, runs, strict=True):
        doc = (example.read_text().split('"""')[1].strip().splitlines() or [""])[0]
        lines += [f"## `{example.name}`", "", doc, "",
                  "```text", f"python examples/{example.name} OUT", run["stdout"], "```", ""]
        lines += [f"![{example.stem}: {picture}](gallery/{example.stem}/{picture})"
                  for picture in run["pictures"]]
        lines.append("")
    (out / "gallery.md").write_text("\n".join(lines))


def _more_page(docs: Path, out: Path) -> None:
    pages = sorted(p.stem for p in docs.glob("*.md") if p.stem not in LISTED)
    lines = ["# More guides", "", "Pages on one part of mexone each.", "",
             "```{toctree}", ":maxdepth: 1", "", *[f"/{page}" for page in pages], "```", ""]
    (out / "more.md").write_text("\n".join(lines))


def _first_sentence(text: str | None) -> str:
    paragraph = " ".join((text or "").strip().split("\n\n")[0].split())
    return paragraph.split(". ")[0].rstrip(".") + "." if paragraph else ""


def _layout_page(root: Path, out: Path) -> None:
    """docs/contributing.md's Layout: the layers as tests/test_layers.py enforces them (its CORE
    and FRONT_END_ORDER, the one home of the order), each with its docstring's first sentence."""
    import importlib
    import importlib.util

    spec = importlib.util.spec_from_file_location("_layers", root / "tests" / "test_layers.py")
    layers = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(layers)

    def line(name: str) -> str:
        if name == "__main__":
            return "- `__main__`: `python -m mexone`, the same as the `mexone` command."
        module = importlib.import_module(f"mexone.{name}")
        kind = "package" if hasattr(module, "__path__") else "module"
        return f"- `{name}` ({kind}): {_first_sentence(module.__doc__)}"

    levels: dict[int, list[str]] = {}
    for name, level in layers.CORE.items():
        levels.setdefault(level, []).append(name)
    lines = ["`src/mexone/` has one sub-package (or module) per layer. The **core** first, each",
             "layer importing only its own level and the levels before it:", ""]
    for level in sorted(levels):
        lines += [f"**Core, level {level}**", ""]
        lines += [line(name) for name in sorted(levels[level])] + [""]
    lines += ["Then the **front ends**, which the core never imports, each importing the core, its",
              "own front end and those of the levels before it:", ""]
    for level, names in enumerate(layers.FRONT_END_ORDER):
        lines += [f"**Front ends, level {level}**", ""]
        lines += [line(name) for name in sorted(names)] + [""]
    lines += ["No two modules import each other. `tests/test_layers.py` checks all of it, and this",
              "list is generated from it when the site is built.", ""]
    _write_if_changed(out / "layout.md", "\n".join(lines))


def _write_if_changed(path: Path, text: str) -> None:
    if not path.is_file() or path.read_text() != text:
        path.write_text(text)


def generate(app: Sphinx) -> None:
    docs = Path(app.srcdir)
    root = docs.parent
    out = docs / "_generated"
    out.mkdir(exist_ok=True)
    from mexone import ranges

    _write_if_changed(docs / "ranges.md", ranges.docs_page())
    _cli_page(out)
    _layout_page(root, out)
    _api_pages(out)
    _more_page(docs, out)
    _gallery_page(root, out)


def _no_type_docstring(app, what, name, obj, options, lines: list[str]) -> None:
    """A module constant's only docstring is a `#:` comment above it; without one autodoc would
    show its type's (dict's, ndarray's): none then."""
    if what != "data" or not lines:
        return
    from sphinx.pycode import ModuleAnalyzer

    owner, _, attr = name.rpartition(".")
    try:
        commented = ("", attr) in ModuleAnalyzer.for_module(owner).find_attr_docs()
    except Exception:  # noqa: BLE001 (no source to read: keep what autodoc found)
        return
    if not commented:
        lines[:] = []


def setup(app: Sphinx) -> dict:
    app.connect("builder-inited", generate)
    app.connect("autodoc-process-docstring", _no_type_docstring)
    return {"version": "1", "parallel_read_safe": True}
