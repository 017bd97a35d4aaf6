"""Resolving a controller YAML's `type:` to a student's PythonController, as pluginlib resolves C++
controller types, and validating its declared parameters.

A type that is not a shipped ros_controllers type is looked up, in this order::

    <stem>/<Class>       the file <stem>.py (or package <stem>/) next to the YAML, then the module
                         <stem> on sys.path
    <pkg.mod>.<Class>    the dotted module on sys.path (the YAML's folder first)
    any name             an entry point of that name in group `mexone.controllers`
                         (a pip-installed package's `[project.entry-points."mexone.controllers"]`)

Nothing found is one line listing every place searched and the shipped types. A student's file
that fails to import is one line naming their file:line. `load_plugin(..., fresh=True)` imports
the file again (the manager's reload).
"""

from __future__ import annotations

import builtins
import difflib
import importlib
import importlib.util
import inspect
import sys
import traceback
from contextlib import AbstractContextManager
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType, TracebackType
from typing import TYPE_CHECKING, Any

from mexone import signals
from mexone.control import watchdog
from mexone.control.student import COMMAND_INTERFACES, PythonController
from mexone.control.watchdog import GUARD, ControllerHang, Watched
from mexone.errors import InputError, MexoneError, printable
from mexone.ranges import HANG_TIMEOUT, OVERRUNS, UPDATE_RATE, UPDATE_TIME, number_text

if TYPE_CHECKING:
    import importlib.metadata

__all__ = ["Plugin", "Found", "locate", "load_class", "resolve_class", "validate_params", "student_line",
           "ENTRY_POINT_GROUP", "RESERVED_KEYS", "FAULT_MODES"]

ENTRY_POINT_GROUP = "mexone.controllers"
FAULT_MODES = ("hold", "damp")
# the keys of a Python controller's YAML entry that are not its declared parameters
RESERVED_KEYS = ("type", "joints", "joint", "update_rate", "pid", "gains", "on_fault",
                 "max_update_time", "max_overruns", "hang_timeout", "inputs")


@dataclass(frozen=True, eq=False)
class Plugin:
    """A resolved Python controller type and what its YAML entry says about running it."""

    type: str
    cls: builtins.type[PythonController]
    origin: str  # where it was found, for messages ("/x/my_controllers.py", "module pkg.mod")
    yaml_dir: Path | None
    raw: dict[str, tuple[Any, int | None]] = field(default_factory=dict)  # YAML value, line
    params: dict[str, Any] = field(default_factory=dict)  # validated, defaults filled in
    update_rate: float | None = None  # Hz; None: every control period
    on_fault: str = "hold"
    max_update_time: float | None = None  # s of wall time; None: the period
    max_overruns: int = 10  # consecutive overrunning updates that are a fault
    hang_timeout: float = 2.0  # s of wall time after which a running update is interrupted
    source: Path | None = None  # the YAML
    line: int | None = None  # of the controller in the YAML
    lines: dict[str, int] = field(default_factory=dict)  # each key of the entry -> its line
    inputs: dict[str, str] = field(default_factory=dict)  # declared input -> "controller/export"
    handed: bool = False  # the class was handed over in Python (load_control_config's classes)

    @property
    def interface(self) -> str:
        return COMMAND_INTERFACES[self.cls.command_interface]

    @property
    def isolated(self) -> bool:
        """The class runs in a process of its own (control/worker.py): `cls` stands for it."""
        return getattr(self.cls, "_mexone_worker", None) is not None

    @property
    def file(self) -> str:
        """The student's source file (for file:line in messages)."""
        info = getattr(self.cls, "_mexone_worker", None)
        if info is not None:
            return info.file
        try:
            return inspect.getsourcefile(self.cls) or self.origin
        except TypeError:  # a class whose module is not imported by name (a notebook's)
            code = getattr(getattr(self.cls, "update", None), "__code__", None)
            return code.co_filename if code is not None else self.origin


def student_line(file: str, tb: TracebackType | None) -> int | None:
    """The line of the innermost traceback frame in `file` (their code, not numpy's)."""
    line = None
    for frame in traceback.extract_tb(tb):
        if _same(frame.filename, file):
            line = frame.lineno
    return line


def _same(a: str, b: str) -> bool:
    try:
        return Path(a).resolve() == Path(b).resolve()
    except OSError:
        return a == b


def _import_failure(exc: BaseException, file: str | None, what: str) -> InputError:
    """One line for a student's module that failed to import: their file:line and the error."""
    if isinstance(exc, SyntaxError):
        where = f"{exc.filename}:{exc.lineno}" if exc.filename else (file or what)
        return InputError(f"importing {what} failed: {where}: SyntaxError: {exc.msg}",
                          hint="fix the file; Reload imports it again")
    frames = traceback.extract_tb(exc.__traceback__)
    ours = [f for f in frames if file and _same(f.filename, file)]
    frame = ours[-1] if ours else (frames[-1] if frames else None)
    where = f"{frame.filename}:{frame.lineno}: " if frame else ""
    if isinstance(exc, ControllerHang):
        signals.recover()  # a signal may have woken a blocked import
        return InputError(f"importing {what} did not finish within "
                          f"{number_text(watchdog.STUDENT_SETUP_TIMEOUT)} s (interrupted at "
                          f"{where.rstrip(': ') or what})", hint="fix the file; Reload imports it again")
    text = exc.one_line() if isinstance(exc, MexoneError) else str(exc)
    return InputError(f"importing {what} failed: {where}{type(exc).__name__}: {text}",
                      hint="fix the file; Reload imports it again")


def _watched(what: str, file: str | None) -> AbstractContextManager[None]:
    """An import of a student's code under the watchdog: a module-level infinite loop is
    interrupted (ControllerHang, then one line) instead of freezing the lab."""
    return GUARD.watching(Watched(f"controller code {what}", file or what, "import"))


def _exec_file(path: Path, stem: str) -> ModuleType:
    """Import `path` as a fresh module (named `stem` unless sys.modules holds another module of
    that name); its folder goes on sys.path so it can import its neighbours."""
    name = stem
    old = sys.modules.get(stem)
    if old is not None and not _same(getattr(old, "__file__", "") or "", str(path)):
        name = f"_mexone_controllers_{stem}"
    folder = str(path.parent)
    if folder not in sys.path:
        sys.path.append(folder)
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise InputError(f"cannot import {path}", hint="a controller file must be a .py file")
    module = importlib.util.module_from_spec(spec)
    previous = sys.modules.get(name)
    sys.modules[name] = module  # dataclasses and pickle look their module up here
    try:
        with _watched(path.name, str(path)):
            spec.loader.exec_module(module)
    except BaseException as exc:
        if previous is not None:
            sys.modules[name] = previous
        else:
            sys.modules.pop(name, None)
        if isinstance(exc, KeyboardInterrupt):
            raise
        raise _import_failure(exc, str(path), path.name) from None
    return module


def _import_module(name: str, fresh: bool) -> ModuleType | None:
    """Module `name` from sys.path (re-executed if `fresh`), or None if there is none."""
    try:
        if importlib.util.find_spec(name) is None:
            return None
    except (ImportError, ValueError):
        return None
    try:
        with _watched(f"module {name}", None):
            module = importlib.import_module(name)
            if fresh:
                module = importlib.reload(module)
    except BaseException as exc:
        if isinstance(exc, KeyboardInterrupt):
            raise
        spec = importlib.util.find_spec(name)
        raise _import_failure(exc, spec.origin if spec else None, f"module {name}") from None
    return module


def _class_from(module: ModuleType, cls_name: str, where: str) -> type[PythonController]:
    cls = getattr(module, cls_name, None)
    if cls is None:
        found = sorted(n for n, v in vars(module).items() if isinstance(v, type)
                       and issubclass(v, PythonController) and v is not PythonController)
        raise InputError(f"{where} has no class '{cls_name}'",
                         hint="its controllers: " + (", ".join(found) or "none"))
    if not (isinstance(cls, type) and issubclass(cls, PythonController)):
        raise InputError(f"{cls_name} in {where} is not a mexone.control.PythonController",
                         hint="write class " + cls_name + "(PythonController)")
    return cls


def _entry_point(ctype: str) -> importlib.metadata.EntryPoint | None:
    import importlib.metadata  # here: a controller's worker that never looks one up skips it

    try:
        points = importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)
    except Exception:  # noqa: BLE001 - a broken installed distribution must not stop the lookup
        return None
    return next((p for p in points if p.name == ctype), None)


@dataclass(frozen=True)
class Found:
    """Where a `type:` is, found without importing anything: a file beside the YAML ("file",
    its path), a module on sys.path ("module", its dotted name) or an entry point ("entry",
    its name); `cls_name` the class asked for (entry points name their own)."""

    kind: str
    name: str
    cls_name: str

    @property
    def own(self) -> bool:
        """mexone's own code (`mexone/StateFeedback`): trusted, it runs in the lab's process."""
        top = self.name.partition(":")[0] if self.kind == "entry" else self.name
        return self.kind != "file" and top.split(".")[0] == "mexone"


def locate(ctype: str, yaml_dir: Path | None, shipped: list[str]) -> Found:
    """Where `ctype` is, in pluginlib's order (this module's docstring), or an InputError listing
    what was searched. Nothing is imported: a student's module runs only where it is imported
    (a controller's own process, or `resolve_class`)."""
    searched: list[str] = []
    if "/" in ctype:
        stem, _, cls_name = ctype.rpartition("/")
        if stem in {known.partition("/")[0] for known in shipped}:  # a shipped type, misspelt
            close = difflib.get_close_matches(ctype, shipped, n=1)
            raise InputError(f"unknown controller type '{printable(ctype, 120)}'",
                             hint=(f"did you mean '{close[0]}'? " if close else "")
                             + "shipped types: " + ", ".join(sorted(shipped)))
        if stem and cls_name and "/" not in stem and stem.isidentifier():
            if yaml_dir is not None:
                for path in (yaml_dir / f"{stem}.py", yaml_dir / stem / "__init__.py"):
                    searched.append(f"{path.relative_to(yaml_dir)} beside the YAML")
                    if path.is_file():
                        return Found("file", str(path), cls_name)
            searched.append(f"module '{stem}' on sys.path")
            if _module_exists(stem, None):
                return Found("module", stem, cls_name)
    elif "." in ctype:
        mod_name, _, cls_name = ctype.rpartition(".")
        searched.append(f"module '{mod_name}' on sys.path")
        if all(part.isidentifier() for part in mod_name.split(".")) and \
                _module_exists(mod_name.split(".")[0], yaml_dir):
            return Found("module", mod_name, cls_name)
    searched.append(f"entry points '{ENTRY_POINT_GROUP}'")
    point = _entry_point(ctype)
    if point is not None:
        return Found("entry", point.value, "")
    raise InputError(f"unknown controller type '{printable(ctype, 120)}': searched "
                     f"{', '.join(printable(s, 200) for s in searched)}",
                     hint=_beside_hint(ctype, yaml_dir) + "shipped types: " + ", ".join(sorted(shipped)))


def _module_exists(top: str, yaml_dir: Path | None) -> bool:
    """Whether top-level module `top` is there (beside the YAML or on sys.path), unimported."""
    if yaml_dir is not None and ((yaml_dir / f"{top}.py").is_file() or
                                 (yaml_dir / top / "__init__.py").is_file()):
        return True
    try:
        return importlib.util.find_spec(top) is not None
    except (ImportError, ValueError):
        return False


def resolve_class(ctype: str, yaml_dir: Path | None, shipped: list[str],
                  fresh: bool = False) -> tuple[type[PythonController], str]:
    """The class `ctype` names and where it came from, imported here, or an InputError listing
    what was searched (no location: the caller adds the YAML's file:line)."""
    return load_class(ctype, locate(ctype, yaml_dir, shipped), yaml_dir, fresh)


def load_class(ctype: str, found: Found, yaml_dir: Path | None,
               fresh: bool = False) -> tuple[type[PythonController], str]:
    """Import the class `locate` found for `ctype` (in a controller's own process, or here for
    mexone's own and for `mexone check`): the class and where it came from."""
    if found.kind == "file":
        path = Path(found.name)
        return _class_from(_exec_file(path, path.parent.name if path.name == "__init__.py"
                                      else path.stem), found.cls_name, path.name), str(path)
    if found.kind == "module":
        if "." in found.name and yaml_dir is not None and str(yaml_dir) not in sys.path:
            sys.path.append(str(yaml_dir))
        module = _import_module(found.name, fresh)
        if module is None:
            raise InputError(f"unknown controller type '{ctype}': module '{found.name}' not found")
        return _class_from(module, found.cls_name, f"module {found.name}"), f"module {found.name}"
    module_name, _, attribute = found.name.partition(":")
    try:
        with _watched(f"entry point {found.name}", None):
            cls = importlib.import_module(module_name)
            if fresh:
                cls = importlib.reload(cls)
            for part in attribute.split(".") if attribute else ():
                cls = getattr(cls, part)
    except BaseException as exc:
        if isinstance(exc, KeyboardInterrupt):
            raise
        raise _import_failure(exc, None, f"entry point {found.name}") from None
    if not (isinstance(cls, type) and issubclass(cls, PythonController)):
        raise InputError(f"entry point '{ctype}' ({found.name}) is not a PythonController")
    return cls, f"entry point {found.name}"


def _beside_hint(ctype: str, yaml_dir: Path | None) -> str:
    """'did you mean ...?' for a misspelt file stem: a student's typo in `type:`, with their
    file right there beside the YAML."""
    stem, _, cls_name = ctype.rpartition("/")
    if not stem or yaml_dir is None or not yaml_dir.is_dir():
        return ""
    try:
        beside = sorted(p.stem for p in yaml_dir.glob("*.py"))[:1000]
    except OSError:
        return ""
    close = difflib.get_close_matches(stem, beside, n=1)
    return (f"did you mean '{close[0]}/{cls_name}', the {close[0]}.py beside the YAML? "
            if close else "")


def validate_params(cls: type[PythonController], raw: dict[str, tuple[Any, int | None]],
                    controller: str, source: Path | str | None) -> dict[str, Any]:
    """The declared parameters' values: the YAML's (each checked, its file:line on a refusal)
    over the defaults. A key the class does not declare is refused (a typo never passes
    silently)."""
    declared = cls.declared_params()
    clash = sorted(set(declared) & set(RESERVED_KEYS))
    if clash:
        raise InputError(f"controller '{controller}': {cls.__name__} declares parameter "
                         f"'{clash[0]}', a name the YAML uses for itself", hint="rename the Param")
    values = {name: p.default for name, p in declared.items()}
    where = source or "<controllers>"
    for key, (value, line) in raw.items():
        param = declared.get(key)
        if param is None:
            raise InputError(f"controller '{controller}': {cls.__name__} has no parameter '{key}'",
                             file=where, line=line,
                             hint="its parameters: " + (", ".join(declared) or "none"))
        values[key] = param.check(value, f"controller '{controller}': {key}", file=where,
                                  line=line)
    return values


def check_settings(fields: dict[str, tuple[Any, int | None]], controller: str,
                   source: Path | str | None) -> dict[str, Any]:
    """The running settings of a Python controller's YAML entry (update_rate, on_fault, ...)."""
    where = source or "<controllers>"
    out: dict[str, Any] = {}
    for key, valid in (("update_rate", UPDATE_RATE), ("max_update_time", UPDATE_TIME),
                       ("max_overruns", OVERRUNS), ("hang_timeout", HANG_TIMEOUT)):
        if key in fields:
            value, line = fields[key]
            out[key] = valid.check(value, f"controller '{controller}': {key}", file=where,
                                   line=line)
    if "on_fault" in fields:
        value, line = fields["on_fault"]
        if value not in FAULT_MODES:
            raise InputError(f"controller '{controller}': on_fault {value!r:.40} must be "
                             f"{' or '.join(FAULT_MODES)}", file=where, line=line)
        out["on_fault"] = value
    return out
