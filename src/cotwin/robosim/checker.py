"""What every per-notation checker shares: the project, the file being checked, its types and functions."""

from __future__ import annotations

from ..diagnostics import Diagnostics
from .declarations import SourceFile
from .types import TypeResolver


class Checker:
    def __init__(self, project, source: SourceFile, diag: Diagnostics):
        self.project = project
        self.source = source
        self.diag = diag
        self.types = TypeResolver(project, source, diag)
        self.functions = project.visible_functions(source)
