"""A layered drawing of a directed graph (a state machine): nodes in rows by their distance from the
start, ordered within rows to keep edges short, placed on a grid. Deterministic: the same graph gives
the same coordinates, so the page draws the model as the model is, not as a browser's force layout
happens to settle.

It is the simple part of Sugiyama's method: breadth-first rows (back edges are whatever points up),
a few barycentre sweeps to order each row, and rows centred on the widest one.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Box:
    """A node to place: its id and size (points)."""

    id: str
    width: float
    height: float


@dataclass(frozen=True)
class Placed:
    id: str
    x: float  # centre
    y: float  # centre
    width: float
    height: float
    row: int


def rows_from(nodes: list[str], edges: list[tuple[str, str]], starts: list[str]) -> dict[str, int]:
    """Row of every node: breadth-first distance from the starts; nodes not reached from them go
    below, each from its own first unplaced node in declaration order."""
    succ: dict[str, list[str]] = {n: [] for n in nodes}
    for a, b in edges:
        if a in succ and b in succ and b not in succ[a]:
            succ[a].append(b)
    row: dict[str, int] = {}
    frontier = [n for n in starts if n in succ]
    base = 0
    while True:
        for n in frontier:
            row.setdefault(n, base)
        while frontier:
            nxt = []
            for n in frontier:
                for m in succ[n]:
                    if m not in row:
                        row[m] = row[n] + 1
                        nxt.append(m)
            frontier = nxt
        rest = [n for n in nodes if n not in row]
        if not rest:
            return row
        base = max(row.values(), default=-1) + 1
        frontier = [rest[0]]


def order_rows(rows: dict[str, int], nodes: list[str], edges: list[tuple[str, str]], sweeps: int = 4) -> list[list[str]]:
    """Nodes per row, ordered by the barycentre of their neighbours in the rows above and below."""
    depth = max(rows.values(), default=-1) + 1
    layers = [[n for n in nodes if rows[n] == r] for r in range(depth)]
    neighbours: dict[str, set[str]] = {n: set() for n in nodes}
    for a, b in edges:
        if a in neighbours and b in neighbours and a != b:
            neighbours[a].add(b)
            neighbours[b].add(a)

    def sweep(order: range, side: int) -> None:
        for r in order:
            ref = r + side
            if not 0 <= ref < depth:
                continue
            pos = {n: i for i, n in enumerate(layers[ref])}
            current = {n: i for i, n in enumerate(layers[r])}

            def key(n: str) -> tuple[float, int]:
                near = [pos[m] for m in neighbours[n] if m in pos]
                return (sum(near) / len(near) if near else current[n], current[n])

            layers[r] = sorted(layers[r], key=key)

    for _ in range(sweeps):
        sweep(range(1, depth), -1)
        sweep(range(depth - 2, -1, -1), +1)
    return layers


def layered(boxes: list[Box], edges: list[tuple[str, str]], starts: list[str], gap_x: float = 24.0,
            gap_y: float = 40.0) -> list[Placed]:
    """Place `boxes` in rows (top to bottom) by distance from `starts` (see module doc)."""
    ids = [b.id for b in boxes]
    size = {b.id: b for b in boxes}
    layers = order_rows(rows_from(ids, edges, starts), ids, edges)
    widths = [sum(size[n].width for n in layer) + gap_x * max(len(layer) - 1, 0) for layer in layers]
    widest = max(widths, default=0.0)
    out: list[Placed] = []
    y = 0.0
    for r, layer in enumerate(layers):
        height = max((size[n].height for n in layer), default=0.0)
        x = (widest - widths[r]) / 2
        for n in layer:
            b = size[n]
            out.append(Placed(n, x + b.width / 2, y + height / 2, b.width, b.height, r))
            x += b.width + gap_x
        y += height + gap_y
    return out
