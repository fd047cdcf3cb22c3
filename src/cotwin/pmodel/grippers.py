"""The grippers of a kinematic tree: the links carrying two prismatic fingers or more, the tools the IK takes for
a gripper (cotwin.pmodel.ik.find_tool takes the last of them by default). A robot of two arms has two, so which
arm the IK drives by default is a choice to say, and a mapping driving the other names its gripper."""

from __future__ import annotations


def gripper_links(tree) -> list[str]:
    """The links below a moving joint carrying two prismatic joints or more, in the tree's order: a gripper is on an
    arm (TIAGo dual's base_link, carrying its two wheel suspensions, was taken for its gripper, the IK's arm empty)."""
    parent_of = {j.child: j for j in tree.joints}

    def moved(link: str) -> bool:
        while link in parent_of:
            joint = parent_of[link]
            if joint.kind != "fixed":
                return True
            link = joint.parent
        return False

    return [link.name for link in tree.links if moved(link.name)
            and sum(1 for j in tree.joints if j.parent == link.name and j.kind == "prismatic") >= 2]


def beyond(tree, joint: str) -> list[str]:
    """The grippers the joint moves (those whose path from the root passes through it), nearest first."""
    parent_of = {j.child: (j.parent, j.name) for j in tree.joints}

    def through(link: str) -> int | None:  # joints from `joint` to the link, None when the path misses it
        steps = 0
        while link in parent_of:
            link, name = parent_of[link]
            if name == joint:
                return steps
            steps += 1
        return None

    found = [(through(g), g) for g in gripper_links(tree)]
    return [g for steps, g in sorted((s, g) for s, g in found if s is not None)]
