"""One-line descriptions of what a file declares, for `cotwin check`."""

from __future__ import annotations

from .declarations import EnumDecl, FunctionDecl, RecordDecl, SourceFile
from .dmodel_elements import Controller, Interface, Module, StateMachine
from .machines import MachineGraph
from .pmodel_elements import Device, Mapping, PModel


def _count(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def summarise(source: SourceFile) -> str:
    parts = []
    counts = [
        (Interface, "interface"), (RecordDecl, "record"), (EnumDecl, "enumeration"), (FunctionDecl, "function"),
        (Device, "device"), (Controller, "controller"), (Module, "module"), (Mapping, "mapping"),
    ]
    for cls, word in counts:
        n = len(source.of_kind(cls))
        if n:
            parts.append(_count(n, word))
    for stm in source.of_kind(StateMachine):
        graph = MachineGraph(stm)
        parts.append(f"stm {stm.name}: {_count(len(graph.states), 'state')}, "
                     f"{_count(len(graph.edges), 'transition')}")
    for pm in source.of_kind(PModel):
        joints = sum(len(link.joints) for link in pm.links)
        parts.append(f"pmodel {pm.name}: {_count(len(pm.links), 'link')}, {_count(joints, 'joint')}")
    return ", ".join(parts) or "empty"
