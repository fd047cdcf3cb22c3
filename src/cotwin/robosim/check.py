"""Check a whole project: parse every file, resolve names across files, type-check, report all findings."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

from ..diagnostics import CotwinError, Diagnostics, Finding, Severity
from .check_dmodel import DModelChecker
from .check_mapping import MappingChecker
from .check_pmodel import PModelChecker
from .project import Project, load_project, project_groups


@dataclass
class CheckResult:
    projects: list[Project]
    findings: list[Finding]

    @property
    def project(self) -> Project:
        return self.projects[0]

    @property
    def ok(self) -> bool:
        return not any(f.severity is Severity.ERROR for f in self.findings)

    def raise_if_errors(self) -> "CheckResult":
        if not self.ok:
            raise CotwinError(self.findings)
        return self


def check_project(project: Project, diag: Diagnostics) -> None:
    """Run every checker over every file of an already loaded project."""
    for source in project.files:
        if source.notation == "rst":
            DModelChecker(project, source, diag).check()
        else:
            DModelChecker(project, source, diag).check()  # enumerations, records, functions in .pm
            PModelChecker(project, source, diag).check()
            MappingChecker(project, source, diag).check()
    diag.extend(project.scope_findings.values())


def check_paths(paths: Iterable[str | Path]) -> CheckResult:
    """Check the model files under `paths`, one project per folder (see `project_groups`)."""
    groups, findings = project_groups(paths)
    diag = Diagnostics()
    diag.extend(findings)
    projects = []
    for files in groups:
        project = load_project(files, diag)
        check_project(project, diag)
        projects.append(project)
    return CheckResult(projects, diag.findings)


def load_checked(paths: Iterable[str | Path]) -> Project:
    """One project made of all the model files under `paths`, with no errors, or CotwinError
    listing every finding."""
    return load_checked_warned(paths)[0]


def load_checked_warned(paths: Iterable[str | Path]) -> tuple[Project, list[Finding]]:
    """`load_checked` and the warnings found on the way (what `cotwin check` shows), for a command that
    shows them too (`cotwin run`)."""
    diag = Diagnostics()
    project = load_project(paths, diag)
    check_project(project, diag)
    diag.raise_if_errors()
    return project, [f for f in diag.findings if f.severity is Severity.WARNING]
