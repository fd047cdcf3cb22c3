"""Deterministic XML text and number formatting for the exporters (same model -> same bytes)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from .tree import matrix_rpy


def num(x: float) -> str:
    text = f"{float(x):.12g}"
    return "0" if text in ("-0", "0", "-0.0") else text


def file_uri(path: str | Path) -> str:
    """A mesh's file:// URI with '%', '#' and '?' escaped: `file:///a/my #1 robot/x.stl` written raw was cut at
    the '#' (a fragment) by every reader, cotwin's import too. Other characters stay as written (a space too:
    Gazebo reads the path after file:// without decoding it)."""
    return "file://" + "".join(_URI_ESCAPES.get(c, c) for c in str(Path(path).absolute()))


_URI_ESCAPES = {"%": "%25", "#": "%23", "?": "%3F"}


def nums(values) -> str:
    return " ".join(num(v) for v in values)


def pose_text(T: np.ndarray) -> str:
    """`x y z roll pitch yaw` of a 4x4 transform (SDF <pose>)."""
    return nums([*T[:3, 3], *matrix_rpy(T[:3, :3])])


def quat(R: np.ndarray) -> tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z) of a rotation matrix, w >= 0 (MuJoCo's convention)."""
    m = R
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = np.sqrt(tr + 1.0) * 2
        q = (0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s)
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        q = ((m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s)
    elif m[1, 1] > m[2, 2]:
        s = np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        q = ((m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s)
    else:
        s = np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        q = ((m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s)
    q = np.array(q) / np.linalg.norm(q)
    return tuple(-q if q[0] < 0 else q)


def sub(parent: ET.Element, tag: str, text: str | None = None, **attrs) -> ET.Element:
    el = ET.SubElement(parent, tag, {k.rstrip("_"): v for k, v in attrs.items()})
    if text is not None:
        el.text = text
    return el


def to_text(root: ET.Element) -> str:
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
