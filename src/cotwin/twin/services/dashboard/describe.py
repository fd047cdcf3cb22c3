"""What the page draws that does not change during a run, derived from the twin's models: the d-model's
state machines (nodes, transitions, a layout), the robot's links and joints with their geometry from
the kinematic tree (the same one SDF, URDF and MJCF are written from), the scene's drawing, the
observed variables and the commands the panel can send. Plain JSON-ready data.
"""

from __future__ import annotations

import numpy as np

from ....robosim.dmodel_elements import Final, Initial, Junction
from ...assembly.system import MAPPING, RABBITMQ, TwinSystem
from .layout import Box, layered

CHAR_WIDTH = 7.2  # points per character of a 12 pt label
PAD = 14.0  # inside a composite state
TITLE = 20.0  # a composite state's name band


def _matrix(T: np.ndarray) -> list[float]:
    """A 4x4 pose, row-major (three.js Matrix4.set takes this order)."""
    return [round(float(v), 9) for v in np.asarray(T).reshape(16)]


# ---- state machines ---------------------------------------------------------------------------


def _kind(info) -> str:
    node = info.node
    if isinstance(node, Initial):
        return "initial"
    if isinstance(node, Junction):
        return "junction"
    if isinstance(node, Final):
        return "final"
    return "composite" if info.children else "state"


def _size(info) -> tuple[float, float]:
    kind = _kind(info)
    if kind in ("initial", "junction", "final"):
        return 16.0, 16.0
    return max(64.0, CHAR_WIDTH * len(info.name) + 20.0), 30.0


def machine_drawing(program, machine) -> dict:
    """One machine of a d-model Program: its nodes (placed, nested states around their children) and
    transitions, the leaf names its state port indexes, and the port itself."""
    graph = machine.graph
    node_id = {info: ".".join(info.path) for info in graph.nodes}
    placed: dict[str, dict] = {}

    def lift(info, container):
        """The child of `container` that is `info` or holds it (None if outside the container)."""
        while info is not None and info.parent is not container:
            info = info.parent
        return info

    def lay(container) -> tuple[float, float, list[tuple[object, float, float]]]:
        """Lay out a container's children; returns its interior size and (node, x, y) relative to it."""
        children = graph.children_of(container)
        interiors = {}
        boxes = []
        for child in children:
            if _kind(child) == "composite":
                w, h, inner = lay(child)
                interiors[child] = inner
                boxes.append(Box(node_id[child], w + 2 * PAD, h + PAD + TITLE))
            else:
                boxes.append(Box(node_id[child], *_size(child)))
        edges = []
        for e in graph.edges:
            a, b = lift(e.source, container), lift(e.target, container)
            if a is not None and b is not None and a is not b:
                edges.append((node_id[a], node_id[b]))
        initial = graph.initial_of(container)
        starts = [node_id[initial]] if initial is not None else [node_id[c] for c in children[:1]]
        spots = layered(boxes, edges, starts)
        out = []
        by_id = {node_id[c]: c for c in children}
        for p in spots:
            info = by_id[p.id]
            out.append((info, p.x, p.y, p.width, p.height))
            if info in interiors:  # children of a composite, relative to its interior's top left corner
                left, top = p.x - p.width / 2 + PAD, p.y - p.height / 2 + TITLE
                out.extend((i, left + x, top + y, w, h) for i, x, y, w, h in interiors[info])
        width = max((x + w / 2 for _, x, _, w, _ in out), default=0.0)
        height = max((y + h / 2 for _, _, y, _, h in out), default=0.0)
        return width, height, out

    width, height, spots = lay(None)
    margin = 10.0
    for info, x, y, w, h in spots:
        placed[node_id[info]] = {"id": node_id[info], "name": info.name, "kind": _kind(info),
                                 "depth": len(info.path) - 1, "x": round(x + margin, 2), "y": round(y + margin, 2),
                                 "w": round(w, 2), "h": round(h, 2)}
    nodes = [placed[node_id[info]] for info in graph.nodes if node_id[info] in placed]
    nodes.sort(key=lambda n: (n["kind"] != "composite", n["depth"]))  # containers first: drawn behind
    edges = [{"name": e.transition.name, "from": node_id[e.source], "to": node_id[e.target]} for e in graph.edges]
    return {"name": machine.name, "machine": machine.machine.name, "port": program.state_port(machine),
            "leaves": program.leaf_names(machine), "width": round(width + 2 * margin, 2),
            "height": round(height + 2 * margin, 2), "nodes": nodes, "edges": edges}


# ---- the robot and its scene ------------------------------------------------------------------


def robot_drawing(tree, variables: dict[str, str]) -> dict:
    """Links with their geometry (box, cylinder, sphere, capsule; sizes as in the p-model, poses in the
    link frame) and joints as the fixed transforms around their motion, as KinematicTree.forward uses
    them: child = parent @ before @ motion(axis, q) @ after. `variables` maps a joint to the observed
    variable that gives its position."""
    from ....pmodel.tree import inverse

    poses = {l.name: l.pose for l in tree.links}
    links = [{"name": l.name, "geoms": [_geom(g) for g in l.geoms]} for l in tree.links]
    joints = [{"name": j.name, "kind": j.kind, "parent": j.parent, "child": j.child,
               "axis": [round(float(v), 9) for v in j.axis],
               "before": _matrix(inverse(poses[j.parent]) @ j.pose), "after": _matrix(inverse(j.pose) @ poses[j.child]),
               "variable": variables.get(j.name)} for j in tree.joints]
    return {"name": tree.name, "root": tree.root.name, "root_pose": _matrix(tree.root.pose), "links": links,
            "joints": joints}


def _geom(g) -> dict:
    """A geom as the page draws it: a mesh as its bounding box (its size and centre as the tree gives them)."""
    if g.kind != "mesh":
        return {"name": g.name, "kind": g.kind, "size": dict(g.size), "pose": _matrix(g.pose)}
    box = np.eye(4)
    box[:3, 3] = g.center
    return {"name": g.name, "kind": "box", "size": dict(g.size), "pose": _matrix(g.pose @ box), "mesh": True}


def scene_drawing(scene) -> dict | None:
    """What the scene draws on the page (its `drawing()`; None without a scene or drawing)."""
    return scene.drawing() if scene is not None else None


# ---- the whole page ---------------------------------------------------------------------------


def observed_joints(system: TwinSystem) -> dict[str, tuple[str, str]]:
    """Monitored mapping variable -> (the joint it mirrors, position | velocity): TwinModels.mirrors, the joints
    [monitor] joints gives (the arm up to the cell geometry's [tool] link by default), as the mapping mirrors them."""
    return dict(system.models.mirrors)


def _range(sc) -> dict:
    """What the panel's input for a value port may hold beyond its FMI type: an enumeration's literals
    (sent by name), a nat's minimum."""
    from ....robosim.types import NAT, EnumTy

    if isinstance(sc.ty, EnumTy):
        return {"literals": [lit.name for lit in sc.ty.decl.literals]}
    return {"min": 0} if sc.ty == NAT else {}


def command_panel(system: TwinSystem) -> dict:
    """The commands the page may send: the twin's command events with their value ports, and where the
    twin's commands come from (only a RabbitMQ source takes commands from the page)."""
    program = system.models.program
    events = []
    for ev in program.inputs:
        if ev.name not in system.command_events:
            continue
        events.append({"name": ev.name, "values": [{"port": port, "label": "_".join(sc.path) or port,
                                                     "type": sc.fmi_type, **_range(sc)} for port, sc in ev.value_ports]})
    source = "none" if system.source is None else "rabbitmq" if system.source is RABBITMQ else "plan"
    out = {"source": source, "events": events}
    if source == "plan":
        out["plan"] = str(system.spec.plan)
        out["planned"] = [{"time": c.time, "values": dict(c.values)} for c in system.commands]
    if source == "rabbitmq":
        s = system.spec.rabbitmq
        out["broker"] = {"exchange": s.exchange, "to_cosim": s.to_cosim, "from_cosim": s.from_cosim}
    return out


def describe(system: TwinSystem, sides: list[str], mode: str, features: dict | None = None) -> dict:
    """Everything static the page needs (see module doc). `sides`: the co-simulations shown (pt, dt for
    a live twin; twin for one run); `mode`: twin | run | history."""
    spec, models = system.spec, system.models
    joints = observed_joints(system)
    variables = [{"name": v, "key": f"{MAPPING.name}.{v}", "joint": joints[v][0] if v in joints else None,
                  "kind": joints[v][1] if v in joints else "value"} for v in models.monitored]
    positions = {joint: v for v, (joint, kind) in joints.items() if kind == "position"}
    program = models.program
    return {
        "project": str(spec.path), "module": program.module.name, "mode": mode, "sides": list(sides),
        "step": spec.step, "end": spec.end, "algorithm": spec.algorithm,
        "pt": spec.pt.endpoint if spec.pt is not None and "pt" in sides else None,
        "variables": variables,
        "deviation": list(spec.deviation.variables) if spec.deviation.variables is not None else None,
        "machines": [machine_drawing(program, m) for m in program.machines],
        "robot": robot_drawing(models.tree, positions),
        "scene": scene_drawing(models.scene),
        "commands": command_panel(system),
        "features": {"whatif": False, **(features or {})},
    }


# ---- a cell of several robots -----------------------------------------------------------------


def describe_cell(cell, sides: list[str], mode: str, features: dict | None = None) -> dict:
    """What the page draws of a cell of several robots (cotwin.twin.assembly.cell): every robot at its base pose, its
    variables and d-model state machines scoped by its name (`ROBOT.q0`, "ROBOT: Machine"); commands from the
    page to the robot it names when the cell's commands come from the broker (cell_commands)."""
    from ...assembly.cell import CELL_MAPPING

    spec, program = cell.spec, cell.program
    variables, machines, robots = [], [], []
    for robot in cell.robots:
        models = robot.system.models
        joints = models.mirrors  # as the robot's mapping mirrors them
        for v in models.monitored:
            variables.append({"name": robot.scoped(v), "key": f"{CELL_MAPPING.name}.{robot.scoped(v)}",
                              "joint": joints[v][0] if v in joints else None,
                              "kind": joints[v][1] if v in joints else "value"})
        positions = {joint: robot.scoped(v) for v, (joint, kind) in joints.items() if kind == "position"}
        drawing = robot_drawing(models.tree, positions)
        drawing["label"] = robot.name
        drawing["root_pose"] = _matrix(robot.pose @ models.tree.root.pose)
        robots.append(drawing)
        for m in program.machines:
            machine = machine_drawing(program, m)
            machine["name"] = f"{robot.name}: {machine['name']}"
            machines.append(machine)
    return {
        "project": str(spec.path), "module": program.module.name, "mode": mode, "sides": list(sides),
        "step": spec.step, "end": spec.end, "algorithm": spec.algorithm, "pt": "plant" if "pt" in sides else None,
        "variables": variables,
        "deviation": None,
        "machines": machines,
        "robot": robots[0], "robots": robots,
        "scene": scene_drawing(cell.scene),
        "commands": cell_commands(cell),
        "features": {"whatif": False, **(features or {})},
    }


def cell_commands(cell) -> dict:
    """A cell's commands as the page lists them: its plan's, each value scoped by its robot; or, from the
    broker, the command events (one d-model: the same for every robot) with the robots the page may send
    them to, each on its own routing (TO_COSIM.ROBOT)."""
    spec = cell.spec
    if spec.rabbitmq is not None:
        s = spec.rabbitmq
        return {"source": "rabbitmq", "events": command_panel(cell.robots[0].system)["events"],
                "robots": [robot.name for robot in cell.robots],
                "broker": {"exchange": s.exchange, "to_cosim": f"{s.to_cosim}.ROBOT", "from_cosim": f"{s.from_cosim}.ROBOT"}}
    planned = sorted(({"time": c.time, "values": {robot.scoped(p): v for p, v in c.values}}
                      for robot in cell.robots for c in robot.system.commands), key=lambda c: c["time"])
    return {"source": "plan", "plan": str(spec.plan), "planned": planned, "events": []}
