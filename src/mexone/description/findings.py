"""Finding: one thing `mexone check` (or a reader) noticed about a model."""

from __future__ import annotations

from dataclasses import asdict, dataclass

__all__ = ["Finding", "SEVERITIES"]

SEVERITIES = ("error", "warning", "info")


@dataclass(frozen=True)
class Finding:
    code: str  # stable, kebab-case: tests and scripts match on it
    severity: str  # error: will misbehave in simulation; warning: likely wrong; info: to know
    element: str  # e.g. 'link "head"' or 'joint "l_knee"'
    message: str  # what is wrong and what to do, one line
    line: int | None = None
    file: str | None = None  # where line points when it is not the model (a controller YAML)

    def as_dict(self, file: str | None = None) -> dict[str, object]:
        """For --json: file (the model's unless the finding names another) and line included."""
        out = asdict(self)
        out["file"] = self.file or file
        return out

    def one_line(self, file: str | None = None) -> str:
        file = self.file or file
        where = f"{file}:{self.line}: " if file and self.line else ""
        return f"{where}{self.severity}: {self.element}: {self.message} [{self.code}]"
