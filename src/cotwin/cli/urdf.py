"""Commands bringing robots from other formats in: import-urdf."""

from __future__ import annotations

import click

from .common import main, output_folder, report


@main.command("import-urdf")
@click.argument("urdf", type=click.Path(dir_okay=False))
@click.option("-o", "--output", callback=output_folder, required=True,
              help="the folder to write the p-model (ROBOT.pm) and its meshes (meshes/...) into")
@click.option("--package-path", "package_path", multiple=True, type=click.Path(file_okay=False),
              help="a folder that is, or holds, the ROS packages package:// names (repeatable; then ROS_PACKAGE_PATH)")
@click.option("--force", is_flag=True,
              help="replace a p-model or mesh in the output folder that differs from what the import writes")
def import_urdf(urdf: str, output: str, package_path: tuple[str, ...], force: bool) -> None:
    """Write a RoboSim p-model and its meshes from a URDF (docs/urdf-import.md)."""
    from ..pmodel.urdf_import import import_urdf as run

    result = run(urdf, output, list(package_path), force=force)
    kinds = ", ".join(f"{n} {k}" for k, n in result.joints.items() if n)
    meshes = f"; {len(result.meshes)} mesh file(s) under {result.file.parent / 'meshes'}" if result.meshes else ""
    click.echo(f"{result.file}: p-model {result.pmodel}: {result.links} links, {kinds or 'no'} joints{meshes}")
    if result.renamings:
        click.echo("renamed:")
        width = max(len(r.urdf) for r in result.renamings)
        for r in result.renamings:
            click.echo(f"  {r.kind:<5} {r.urdf:<{width}} -> {r.pmodel}  ({r.why})")
    if result.ignored:
        click.echo("left out (no kinematics or inertia in them): "
                   + ", ".join(f"{n} <{tag.rpartition('/')[2]}>" + (f" in <{tag.rpartition('/')[0]}>" if "/" in tag else "")
                               for tag, n in result.ignored.items()))
    if result.devices:
        click.echo("moving joints: command {actuator.port}, then position, velocity and effort readings:")
        for d in result.devices:
            base, _, command = d.command.rpartition("::")
            readings = ", ".join(r.rpartition("::")[2] for r in d.readings.values())
            click.echo(f"  {d.joint} ({d.kind}): {base}::{{{command}; {readings}}}")
        said = _ik_tool(result.file)
        if said:
            click.echo(said)
    else:
        click.echo("no moving joint: nothing for a mapping to command")
    report(result.findings)


def _ik_tool(pmodel) -> str | None:
    """Which link inverse_kinematics takes as the tool by default and so which joints are its arm: a jaw or a
    sensor frame at the end of the longest chain was taken silently (a gripper's revolute jaw as a 7th arm joint)."""
    from ..diagnostics import CotwinError
    from ..pmodel import ik
    from ..pmodel.grippers import gripper_links
    from ..pmodel.tree import build_tree
    from ..robosim.check import load_checked

    try:
        tree = build_tree(load_checked([pmodel]))
        tool = ik.find_tool(tree)
    except CotwinError:  # the p-model's own problems are reported with the import's findings
        return None
    arm = ik.arm_joints(tree, tool)
    if len(arm) < ik.ARM_JOINTS:  # no arm for the IK (a mobile base, a hand): nothing to say
        return None
    hand = tool.hand or tool.link  # a declared grasp frame's hand (cotwin.pmodel.ik.declared_frame)
    carried = [j.name for j in tree.joints if j.parent == hand]  # a hand's fingers (cotwin.pmodel.ik.hand_link)
    why = (f"the link carrying the fingers {', '.join(tool.fingers)}" if tool.fingers
           else f"the hand at the end of the longest chain of moving joints, carrying {', '.join(carried)}" if carried
           else "the end of the longest chain of moving joints")
    if tool.hand:
        why = f"the grasp frame the URDF declares on {hand}, {why}"
    task = ik.task_for(len(arm))
    reaches = f": {ik.REACHES[task]}" if task != "pose" else ""
    others = [g for g in gripper_links(tree) if g != hand] if tool.fingers else \
        [h for h in ik.hands(tree) if h != hand] if carried else []
    kind = "grippers" if tool.fingers else "hands"
    choice = (f"; it is one of {len(others) + 1} {kind} (also {', '.join(others)}): to drive another arm, name its "
              "gripper by [tool] link in the cell geometry (docs/calibration.md)") if others else \
        "; another tool link: [tool] link in the cell geometry (docs/calibration.md)"
    return (f"inverse_kinematics: tool link {tool.link} ({why}), arm joints {', '.join(arm)} ({len(arm)}{reaches})"
            f"{choice}")

