"""The public API is explicit: `mexone.API` lists the modules a student, a teacher and a plug-in
author import; each such module's `__all__` is its public names, every one documented (a
docstring, or a `#:` comment on a constant); docs/reference/api.md says which audience imports
what; the API reference documents exactly those modules. Every other module and name is
internal."""

from __future__ import annotations

import importlib
import inspect
import sys
from pathlib import Path

import pytest

import mexone

ROOT = Path(__file__).resolve().parents[1]
PUBLIC = sorted({m for modules in mexone.API.values() for m in modules})


def _constant_documented(name: str, value: object) -> bool:
    """A `#:` comment where a module of mexone binds `name` to this very object."""
    from sphinx.pycode import ModuleAnalyzer

    for module_name, module in list(sys.modules.items()):
        if not module_name.startswith("mexone") or vars(module).get(name, None) is not value:
            continue
        try:
            if ("", name) in ModuleAnalyzer.for_module(module_name).find_attr_docs():
                return True
        except Exception:  # noqa: BLE001 - no source (a compiled module): look elsewhere
            continue
    return False


def _documented(value: object, name: str) -> bool:
    if inspect.ismodule(value) or inspect.isroutine(value):
        return bool((value.__doc__ or "").strip())
    if inspect.isclass(value):
        return bool((vars(value).get("__doc__") or "").strip())
    return _constant_documented(name, value)


def test_the_audiences_are_the_three_of_the_issue():
    assert set(mexone.API) == {"student", "teacher", "plug-in author"}


@pytest.mark.parametrize("module_name", PUBLIC)
def test_every_public_name_resolves_and_is_documented(module_name):
    module = importlib.import_module(module_name)
    assert (module.__doc__ or "").strip(), f"{module_name} has no docstring"
    names = getattr(module, "__all__", None)
    assert names is not None, f"{module_name} has no __all__: its public names are unsaid"
    missing = [n for n in names if not hasattr(module, n)]
    assert missing == [], f"{module_name}.__all__ names what it does not define: {missing}"
    undocumented = [n for n in names if not _documented(getattr(module, n), n)]
    assert undocumented == [], f"{module_name}: public names without a docstring: {undocumented}"


def test_every_public_method_of_a_public_class_is_documented():
    """A class's methods and properties without a leading underscore are public too (its own
    docstring, or the one it overrides)."""
    seen, undocumented = set(), []
    for module_name in PUBLIC:
        module = importlib.import_module(module_name)
        for name in module.__all__:
            cls = getattr(module, name)
            if not inspect.isclass(cls) or id(cls) in seen or not cls.__module__.startswith("mexone"):
                continue
            seen.add(id(cls))
            for attr, member in vars(cls).items():
                function = member.fget if isinstance(member, property) else \
                    getattr(member, "__func__", member)
                if attr.startswith("_") or not inspect.isfunction(function):
                    continue
                if not (inspect.getdoc(getattr(cls, attr)) or "").strip():
                    undocumented.append(f"{cls.__module__}.{cls.__qualname__}.{attr}")
    assert undocumented == []


def test_the_api_page_says_who_imports_what():
    page = (ROOT / "docs" / "reference" / "api.md").read_text()
    for audience, modules in mexone.API.items():
        assert audience in page
        absent = [m for m in modules if f"`{m}`" not in page]
        assert absent == [], f"docs/reference/api.md does not list {absent} ({audience})"


def test_the_reference_documents_the_public_modules_only():
    sys.path.insert(0, str(ROOT / "docs" / "_ext"))
    try:
        from mexone_docs import public_modules
    finally:
        sys.path.remove(str(ROOT / "docs" / "_ext"))
    assert sorted(m.__name__ for m in public_modules()) == PUBLIC


def test_renamed_names_work_for_one_release_and_say_the_new_name():
    import warnings

    from mexone.control import ControllerInterface
    from mexone.lab import Lab
    from mexone.routines.runner import resolve_routine, shipped_routines

    lab = Lab.create(model=None, controllers=False)
    with pytest.warns(DeprecationWarning, match="Lab.controllers is renamed Lab.manager"):
        assert lab.controllers is lab.manager
    with pytest.warns(DeprecationWarning, match="mexone.control.Controller is renamed"):
        from mexone.control import Controller
    assert Controller is ControllerInterface
    with pytest.warns(DeprecationWarning, match="the routine 'sweep' is renamed 'joint_steps'"):
        assert resolve_routine("sweep") == shipped_routines()["joint_steps"]
    sys.modules.pop("mexone.physics.watchdog", None)
    with pytest.warns(DeprecationWarning, match="mexone.physics.watchdog is renamed"):
        from mexone.physics.watchdog import DivergenceError
    from mexone.physics.divergence import DivergenceError as new

    assert DivergenceError is new
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the new names say nothing
        assert lab.manager is None and resolve_routine("joint_steps").name == "joint_steps.py"


def test_list_controllers_and_its_former_name():
    from mexone.lab import Lab

    manager = Lab.create().manager
    with pytest.warns(DeprecationWarning, match="ControllerManager.list is renamed"):
        assert manager.list() == manager.list_controllers()


def test_a_params_value_type_and_its_former_name():
    """`kind` is a controller's family in mexone.control; a Param's is its value's type."""
    from mexone.control import Param

    gain = Param(2.0, low=0.0)
    assert gain.value_type is float and Param(3).value_type is int
    with pytest.warns(DeprecationWarning, match="Param.kind is renamed Param.value_type"):
        assert gain.kind is float
