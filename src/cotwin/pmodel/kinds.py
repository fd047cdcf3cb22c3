"""What a p-model's joints, actuators and sensors are, for exporters and the simulator (documented rules,
docs/pmodel-notation.md): the motion of a joint, the command an actuator takes, what a sensor measures.

RoboTool's devices say it in equations a solver reads; cotwin reads, in order: SDF annotations, the
joint's motion subspace (`H` of the SKO library, `S` of Featherstone's) or axis constants (`AXIS`,
CGA's `axis_rot`/`axis_lin`), and last the device and port names.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..robosim import syntax as s
from ..robosim.consteval import ConstEnv, try_evaluate
from ..robosim.pmodel_elements import AnnotationRecord, Device

_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


def _vector(value, size: int) -> np.ndarray | None:
    if isinstance(value, tuple) and len(value) == size and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        return np.array([float(v) for v in value])
    return None


def _const(device: Device | None, name: str, env: ConstEnv):
    """The value of a device's constant (or initialised InOut) `name` in env (instantiations applied)."""
    port = device.port(name) if device is not None else None
    if port is None:
        return None
    value = try_evaluate(s.Name(s.QName((name,), port.loc), port.loc), env, None)
    if value is None and port.init is not None:
        value = try_evaluate(port.init, env, None)
    return value


#: SDF joint types an annotation may name, and the tree kind each moves as (docs/pmodel-notation.md, 7)
JOINT_KINDS = {"revolute": "revolute", "continuous": "revolute", "prismatic": "prismatic", "fixed": "fixed",
               "gearbox": "revolute"}
#: SDF joint types cotwin cannot export (an annotation naming one is an error)
UNSUPPORTED_JOINTS = ("ball", "screw", "universal", "revolute2")


@dataclass(frozen=True)
class JointMotion:
    """What a joint does: its tree kind (revolute, prismatic, fixed; None: it cannot be exported), its SDF
    type where that differs (continuous, gearbox), its unit axis in the joint frame, and a note saying a
    reading taken (or, with no kind, why it cannot be exported)."""

    kind: str | None
    axis: np.ndarray
    note: str = ""
    sdf_kind: str = ""


def joint_motion(device: Device | None, type_name: str, annotations: tuple[AnnotationRecord, ...],
                 env: ConstEnv) -> JointMotion:
    """What a joint does, read in order from an SDF-style annotation (`annotation Revolute { axis = Axis {
    xyz = .. } }`), the axis constants (`AXIS`, CGA's `axis_rot`/`axis_lin`), the motion subspace (`H`,
    `S`), the definition's name; with nothing to tell, RoboTool's default: revolute about z."""
    axis = None
    kind = sdf_kind = None
    for ann in annotations:  # SDF-style annotation Revolute { axis = Axis { xyz = (|..|) } }
        named = ann.name.lower()
        if named in UNSUPPORTED_JOINTS:
            return JointMotion(None, np.array(_AXES["z"]), f"its annotation {ann.name} names an SDF {named} joint, "
                               f"which cotwin cannot export (it exports {', '.join(JOINT_KINDS)} joints)")
        if named in JOINT_KINDS:
            kind, sdf_kind = JOINT_KINDS[named], (named if named in ("continuous", "gearbox") else "")
        ax = ann.get("axis")
        if isinstance(ax, AnnotationRecord) and ax.get("xyz") is not None:
            axis = _vector(try_evaluate(ax.get("xyz"), env, None), 3)
    name = (device.name if device is not None else type_name).lower()
    note = ""
    if axis is None:
        for const in ("AXIS", "axis_rot", "axis_lin"):
            value = _vector(_const(device, const, env), 3)
            if value is not None:
                axis = value
                if const == "axis_rot":
                    kind = kind or "revolute"
                elif const == "axis_lin":
                    kind = kind or "prismatic"
                break
    if axis is None:
        for const in ("H", "S"):  # a motion subspace [angular; linear]
            value = _const(device, const, env)
            six = _vector(value, 6)
            if six is not None:
                angular, linear = six[:3], six[3:]
                if np.linalg.norm(angular) > 0:
                    note = "helical: exported as revolute, the pitch is not modelled" if np.linalg.norm(linear) > 0 else ""
                    return JointMotion(kind or "revolute", angular / np.linalg.norm(angular), note, sdf_kind or "")
                if np.linalg.norm(linear) > 0:
                    return JointMotion(kind or "prismatic", linear / np.linalg.norm(linear), "", sdf_kind or "")
            elif isinstance(value, tuple) and value and isinstance(value[0], tuple):
                first = next((_vector(tuple(row[c] for row in value), 6) for c in range(len(value[0]))), None)
                angular = first[:3] if first is not None else np.zeros(3)
                axis = angular / np.linalg.norm(angular) if np.linalg.norm(angular) > 0 else np.array(_AXES["z"])
                return JointMotion(kind or "revolute", axis, f"a joint of {len(value[0])} degrees of freedom: exported "
                                   "as revolute about its first axis, as RoboTool's SDF generator writes it")
        if kind is None and device is not None and device.port("H") is not None and device.port("H").init is None:
            return JointMotion("revolute", np.array(_AXES["z"]), "a joint of several degrees of freedom: exported as "
                               "revolute about z, as RoboTool's SDF generator writes it")
    if kind is None:
        if "prismatic" in name or "slider" in name:
            kind = "prismatic"
        elif "continuous" in name:
            kind, sdf_kind = "revolute", "continuous"
        elif "revolute" in name or "hinge" in name:
            kind = "revolute"
        elif "fixed" in name:
            kind = "fixed"
    if kind is None:  # RoboTool's SDF generator writes such a joint as revolute (its SDF axis default: z)
        kind = "revolute"
        note = ("nothing in its definition says how it moves (no Revolute/Prismatic/... annotation, axis or motion "
                "subspace): revolute about z, as RoboTool's SDF generator writes it")
    if axis is None:
        suffix = name.rstrip("_neg").rsplit("_", 1)[-1] if "_" in name else ""
        axis = np.array(_AXES.get(suffix, _AXES["z"]))
        if name.endswith("_neg"):
            axis = -axis
    norm = np.linalg.norm(axis)
    return JointMotion(kind, axis / norm if norm > 0 else np.array(_AXES["z"]), note, sdf_kind or "")


# ---- actuators ----

#: library actuators whose command is not told by their port names: device -> (command port, mode)
KNOWN_ACTUATORS = {
    "ControlledMotor": ("ControlIn", "velocity"),  # RoboTool's mobile robot maps wheel speeds to ControlIn
    "TrivialMotor": ("TorqueIn", "effort"),
    "DCMotor": ("V", "effort"),
}
_MODE_WORDS = (("position", ("angle", "position", "pos", "theta")),
               ("velocity", ("speed", "vel", "omega", "rate")),
               ("effort", ("torque", "force", "effort", "current")))


def servo_command(device: Device | None) -> tuple[str | None, str]:
    """(command input port, mode) of an actuator: mode is position, velocity or effort."""
    if device is None:
        return None, "position"
    if device.name in KNOWN_ACTUATORS:
        port, mode = KNOWN_ACTUATORS[device.name]
        if device.port(port) is not None:
            return port, mode
    inputs = [p.name for p in device.ports if p.kind == "input"]
    for port in inputs:
        low = port.lower()
        for mode, words in _MODE_WORDS:
            if any(w in low for w in words):
                return port, mode
    low = device.name.lower()
    for mode, words in _MODE_WORDS:
        if any(w in low for w in words):
            return (inputs[0] if inputs else None), mode
    return (inputs[0] if inputs else None), "position"


# ---- sensors ----

SENSOR_QUANTITIES = (("position", "position"), ("angle", "position"), ("vel", "velocity"),
                     ("torque", "effort"), ("force", "effort"))
#: SDF sensor types, by annotation name or device name (lower case, first match wins)
SDF_SENSORS = (("ray", "ray"), ("lidar", "ray"), ("laser", "ray"), ("sonar", "sonar"), ("imu", "imu"),
               ("camera", "camera"), ("contact", "contact"), ("bumper", "contact"), ("gps", "gps"),
               ("altimeter", "altimeter"), ("magnetometer", "magnetometer"), ("forcetorque", "force_torque"),
               ("force_torque", "force_torque"), ("ir", "ray"))


def sensor_quantity(device_name: str, port: str) -> str | None:
    """What a joint sensor measures, from its device and output port names (documented rule)."""
    text = f"{device_name} {port}".lower()
    for key, quantity in SENSOR_QUANTITIES:
        if key in text:
            return quantity
    return None


def body_quantity(sdf_type: str | None, port: str) -> tuple[str, int] | None:
    """What an IMU-like sensor's scalar port reads: (MuJoCo sensor, component), e.g. yaw rate = gyro z."""
    if sdf_type != "imu":
        return None
    low = port.lower()
    if "av" in low or "angular" in low or "gyro" in low:
        return "gyro", 2
    if "lv" in low or "linear" in low or "vel" in low:
        return "velocimeter", 0
    if "acc" in low:
        return "accelerometer", 0
    return None


#: SDF sensor types (and RoboTool's `light`) an annotation on a sensor may name: RoboTool writes a <sensor>
#: of that type, the annotation's name lowercased (`Logical_camera` is `logical_camera`)
SDF_SENSOR_TYPES = frozenset({"air_pressure", "altimeter", "camera", "contact", "depth_camera", "depth",
                              "force_torque", "gps", "gpu_ray", "gpu_lidar", "imu", "lidar", "logical_camera",
                              "magnetometer", "multicamera", "navsat", "ray", "rfid", "rfidtag", "rgbd_camera",
                              "sonar", "thermal_camera", "wireless_receiver", "wireless_transmitter", "light"})


def annotated_sdf_type(annotations: tuple[AnnotationRecord, ...]) -> tuple[str | None, AnnotationRecord | None]:
    """The SDF type a sensor's annotation names, as RoboTool's SDF generator reads it, and that annotation."""
    for ann in annotations:
        if ann.name.lower() in SDF_SENSOR_TYPES:
            return ann.name.lower(), ann
    return None, None


def sdf_sensor_type(device_name: str, annotations: tuple[AnnotationRecord, ...]) -> str | None:
    """What a sensor is for the simulator: its annotation's SDF type, else what its device name says
    (Lidar, IMU, Camera, Sonar, Bumper, GPS: the published models name them so)."""
    named, _ = annotated_sdf_type(annotations)
    if named is not None:
        return {"lidar": "ray", "gpu_ray": "ray", "gpu_lidar": "ray"}.get(named, named)
    for text in [a.name.lower() for a in annotations] + [device_name.lower()]:
        for key, kind in SDF_SENSORS:
            if text == key or (len(key) > 2 and key in text):
                return kind
    return None


# ---- ray sensors (LiDARs, sonars) ----

@dataclass(frozen=True)
class RaySpec:
    """A ray sensor's beams (cotwin.pmodel.kinds.ray_spec): `samples` beams in the sensor's x-y plane
    from `min_angle` to `max_angle` (rad, about its z axis, 0 along its x axis), measuring `range_min`
    to `range_max` (m), a whole scan `update_rate` times a second."""

    samples: int
    min_angle: float
    max_angle: float
    range_min: float
    range_max: float
    update_rate: float

    def angles(self) -> np.ndarray:
        if self.samples == 1:
            return np.array([self.min_angle])
        return np.linspace(self.min_angle, self.max_angle, self.samples)



#: a LiDAR whose annotation leaves a value out, and whose robot profile gives none ([lidar] of the file
#: `[robot] profile` names, cotwin.mapping.profile): a generic planar scanner, one beam a degree all round,
#: 0.1 to 10 m, 10 turns a second. A particular robot's scanner is data its profile holds.
PLANAR_LIDAR = RaySpec(360, 0.0, float(np.radians(359.0)), 0.1, 10.0, 10.0)
#: a sonar without an annotation (or a profile's [sonar]): one beam straight ahead, 2 cm to 4 m, 10 readings a second
SONAR = RaySpec(1, 0.0, 0.0, 0.02, 4.0, 10.0)
RAY_DEFAULTS = {"lidar": PLANAR_LIDAR, "sonar": SONAR}  # by the profile table that replaces each
RAY_QUANTITIES = ("closest_range", "closest_bearing", "range")
_CLOSEST = ("closest", "nearest", "min")


def ray_quantity(port: str) -> str | None:
    """What a ray sensor's scalar port reads, from its name: the closest return's range (`closestDistance`,
    `min_range`) or bearing (`closestAngle`), or the range straight ahead (`range`, `distance`); None for
    other ports (a whole `scan`, a beam model's `measurement` probability)."""
    low = port.lower()
    closest = any(w in low for w in _CLOSEST)
    if closest and any(w in low for w in ("angle", "bearing", "direction")):
        return "closest_bearing"
    if closest and any(w in low for w in ("distance", "range", "dist")):
        return "closest_range"
    if not closest and any(w in low for w in ("distance", "range")) and "max" not in low:
        return "range"
    return None


def _entry(record: dict | None, *path: str):
    """An evaluated annotation's entry at `path` (records nest: ray -> scan -> horizontal -> samples)."""
    for key in path:
        if not isinstance(record, dict):
            return None
        record = next((v for k, v in record.get("entries", ()) if k.lstrip("_") == key), None)
    return record


def ray_spec(sdf_type: str, annotation: dict | None, defaults: dict[str, RaySpec] | None = None) -> RaySpec:
    """The beams of a ray sensor: its SDF annotation's (`Ray { update_rate, ray = RayDetails { scan = Scan {
    horizontal = Scan_horizontal { samples, min_angle, max_angle } } range = Range { min, max } } }`,
    `Sonar { sonar = SonarDetails { min, max } }`), each value not given from `defaults` ("lidar", "sonar":
    a robot profile's), else RAY_DEFAULTS."""
    kinds = {**RAY_DEFAULTS, **(defaults or {})}
    base = kinds["sonar"] if sdf_type == "sonar" else kinds["lidar"]

    def number(value, default: float) -> float:
        return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else default

    if sdf_type == "sonar":
        return RaySpec(1, 0.0, 0.0, number(_entry(annotation, "sonar", "min"), base.range_min),
                       number(_entry(annotation, "sonar", "max"), base.range_max),
                       number(_entry(annotation, "update_rate"), base.update_rate))
    horizontal = ("ray", "scan", "horizontal")
    samples = int(number(_entry(annotation, *horizontal, "samples"), base.samples))
    return RaySpec(max(samples, 1), number(_entry(annotation, *horizontal, "min_angle"), base.min_angle),
                   number(_entry(annotation, *horizontal, "max_angle"), base.max_angle),
                   number(_entry(annotation, "ray", "range", "min"), base.range_min),
                   number(_entry(annotation, "ray", "range", "max"), base.range_max),
                   number(_entry(annotation, "update_rate"), base.update_rate))
