"""The documentation site builds with Sphinx's warnings as errors, and its API reference holds
every name of every public `__all__` in mexone (an undocumented public name fails here). The
build runs the examples for the gallery (cached in docs/_generated/ by their source's hash).
"""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys
import time
import zlib
from pathlib import Path

import pytest

pytest.importorskip("sphinx", reason="the docs extra (sphinx, furo, myst-parser)")
pytest.importorskip("furo", reason="the docs extra (sphinx, furo, myst-parser)")

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def _inventory(path: Path) -> dict[str, str]:
    """objects.inv, Sphinx's index of what the site documents: full name -> role."""
    data = path.read_bytes()
    body = data.split(b"\n", 4)[4]  # four header lines, then zlib
    names = {}
    for line in zlib.decompress(body).decode().splitlines():
        name, role = line.split(" ", 2)[:2]
        names[name] = role
    return names


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("site")
    start = time.monotonic()
    built = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
                            str(DOCS), str(out)], capture_output=True, text=True, timeout=900,
                           env={**__import__("os").environ, "PYTHONPATH": str(ROOT / "src")})
    print(f"\ndocs build: {time.monotonic() - start:.1f} s")
    assert built.returncode == 0, f"sphinx-build -W failed:\n{built.stderr[-5000:]}"
    return out


def test_the_site_builds_without_warnings(site):
    for page in ("index", "_generated/cli", "_generated/api/index", "_generated/gallery", "ranges",
                 "tutorials/first-simulation", "reference/api", "DECISIONS", "contributing"):
        assert (site / f"{page}.html").is_file(), page


def test_every_verb_is_in_the_cli_reference(site):
    from mexone.cli import build_parser

    parser = build_parser()
    (verbs,) = [a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction"]
    html = (site / "_generated" / "cli.html").read_text()
    for verb, sub in verbs.choices.items():
        assert f"mexone {verb}" in html, verb
        for action in sub._actions:  # every option of every verb
            if action.help == argparse.SUPPRESS:  # a renamed option's old name, kept one release
                continue
            for option in action.option_strings:
                assert option in html, f"mexone {verb} {option}"


def test_the_ranges_page_is_generated_with_every_range(site):
    from mexone import ranges

    html = (site / "ranges.html").read_text()
    for r in ranges.RANGES:
        assert f"<td><p>{r.name}</p></td>" in html, r.name


def test_the_gallery_shows_every_example_with_its_picture(site):
    html = (site / "_generated" / "gallery.html").read_text()
    for example in sorted((ROOT / "examples").glob("[0-9][0-9]_*.py")):
        assert example.name in html
        pictures = list((site / "_images").glob("*.png"))
        assert pictures
        assert f'alt="{example.stem}: ' in html, f"{example.name} has no picture in the gallery"


def test_every_public_name_is_in_the_api_reference(site):
    """Every name in every public module's `__all__` (mexone's packages walked) is documented:
    where it is exported, or where the same object is documented (a re-export)."""
    sys.path.insert(0, str(DOCS / "_ext"))
    try:
        from mexone_docs import public_modules
    finally:
        sys.path.remove(str(DOCS / "_ext"))
    documented = _inventory(site / "objects.inv")
    by_leaf: dict[str, list[str]] = {}
    for name in documented:
        by_leaf.setdefault(name.rpartition(".")[2], []).append(name.rpartition(".")[0])

    def same_object_documented(leaf: str, value) -> bool:
        for owner in by_leaf.get(leaf, []):
            try:
                module = importlib.import_module(owner)
            except ImportError:  # a class's attribute: not a module
                continue
            if getattr(module, leaf, None) is value:
                return True
        return False

    modules = public_modules()
    assert len(modules) > 10  # mexone.API's modules (the public API; the rest is internal)
    missing = []
    for module in modules:
        for name in module.__all__:
            full = f"{module.__name__}.{name}"
            if not hasattr(module, name):
                missing.append(f"{full} (in __all__, not defined)")
            elif full not in documented and not same_object_documented(name, getattr(module, name)):
                missing.append(full)
    assert not missing, f"{len(missing)} public names not in the API reference: {missing[:20]}"
