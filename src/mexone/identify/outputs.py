"""What `identify -o DIR` writes, decided before the fit (so a file in the way is one line before
minutes of work, not after) and written after it (also after Ctrl-C: the best fit so far).

    DIR/<model>.urdf          the student's URDF, only the identified values changed, commented
    DIR/<controllers>.yaml    the controllers YAML with identified p and d (with --params gains)
    DIR/identify.json         what --json prints
    DIR/report.md             the report, with DIR/<bag>.png per bag
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from mexone import signals
from mexone.errors import InputError
from mexone.files import check_output, replacing, usable, write_text
from mexone.identify.patch import Change, patch_controllers, patch_urdf, patched_model_text
from mexone.identify.report import figure_name, markdown, plot_bag
from mexone.identify.session import Result

__all__ = ["Plan", "plan_outputs", "write_outputs", "changes"]


@dataclass(frozen=True)
class Plan:
    folder: Path
    urdf: Path
    controllers: Path | None
    json: Path
    report: Path
    figures: list[Path]
    force: bool


def plan_outputs(folder: Path, model_source: Path, controllers_source: Path | None,
                 gains: bool, bags: list[Path], force: bool) -> Plan:
    """The files to write, each checked now: a folder that is a file, or a file that exists
    without --force, is refused before any work."""
    folder = usable(Path(folder))
    if folder.exists() and not folder.is_dir():
        raise InputError("is a file; -o names the folder identify writes into", file=folder)
    stems = [Path(b).stem for b in bags]
    twice = sorted({s for s in stems if stems.count(s) > 1})
    if twice:
        raise InputError(f"two bags are named {twice[0]}: their report figures would collide",
                         hint="rename one of them")
    urdf = folder / (Path(model_source).stem + ".urdf")
    yaml = folder / Path(controllers_source).name if gains and controllers_source else None
    plan = Plan(folder, urdf, yaml, folder / "identify.json", folder / "report.md",
                [folder / f"{s}.png" for s in stems], force)
    if folder.exists():
        for path in [plan.urdf, plan.controllers, plan.json, plan.report, *plan.figures]:
            if path is not None:
                check_output(path, force)
    return plan


def changes(result: Result) -> list[Change]:
    fit = result.fit
    return [Change(u.kind, u.target, u.component, float(fit.nominal[i]), float(fit.values[i]),
                   None if fit.halfwidth is None else float(fit.halfwidth[i]))
            for i, u in enumerate(fit.unknowns) if not u.nuisance]


def _origin(result: Result) -> str:
    bags = ", ".join(e.name for e in result.experiments)
    return f"fitted to {bags}" + (" (interrupted: best so far)" if result.fit.interrupted else "")


def write_outputs(result: Result, plan: Plan) -> list[str]:
    """Write every planned file; returns notes (gains that could not be written back)."""
    try:
        plan.folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the output folder: {exc.strerror or exc}",
                         file=plan.folder) from None
    every = changes(result)
    origin = _origin(result)
    model_changes = [c for c in every if c.kind != "gains"]
    source = result.robot.source
    notes: list[str] = []
    with signals.finishing():
        if source is not None and source.suffix.lower() == ".urdf":
            text = patch_urdf(source.read_text(), model_changes, origin)
        else:
            text = patched_model_text(result.robot, model_changes, origin)
            notes.append(f"{source.name if source else 'the model'} is not a plain URDF: "
                         f"{plan.urdf.name} is the expanded model as URDF with the changes")
        write_text(plan.urdf, text, plan.force)
        outputs = {"patched URDF": plan.urdf.name}
        gains = [c for c in every if c.kind == "gains"]
        if plan.controllers is not None and gains:
            config = result.config
            joint_controller = {j: name for name, spec in config.controllers.items()
                                for j in spec.joints}
            yaml_text, missed = patch_controllers(config.source.read_text(), config.source, gains,
                                                  joint_controller, origin)
            notes += missed
            write_text(plan.controllers, yaml_text, plan.force)
            outputs["patched controllers"] = plan.controllers.name
        write_text(plan.json, json.dumps(result.as_json(), indent=1) + "\n", plan.force)
        outputs["values as JSON"] = plan.json.name
        result.notes.extend(notes)
        figures = not result.fit.interrupted  # a stopped run ends in seconds: plots take longer
        for before, after in zip(result.before, result.after, strict=True) if figures else ():
            with replacing(plan.folder / figure_name(before), plan.force) as temporary:
                plot_bag(before, after, temporary)
        write_text(plan.report, markdown(result, outputs, figures), plan.force)
    return notes
