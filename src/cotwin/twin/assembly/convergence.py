"""Convergence: a live twin's DT pulled towards its PT, as the `[convergence]` table of a project says.

    [convergence]
    resync = "on-alarm"       # "never" (default) | "on-alarm" | "every N steps"
    estimate = "payload"      # "none" (default) | "payload": the mass at the tool, from the PT's joint torques
    payload_std = 0.05        # kg: the estimate is applied to the DT once its standard deviation is below this
    rest_speed = 0.002        # rad/s (m/s): torques are taken only while every joint is slower than this

Resync puts the PT's measured joint positions and velocities into the DT between two steps (on-alarm: at
every step in which a deviation alarm is raised or still open; every N steps: at steps N, 2N, ...); a
move in progress continues from the new state (cotwin.mapping.endpoint.retimed) and the mapping reads the
new state at once. Each resync is a correction in the history (time, reason, size: the largest joint
difference it removed) and a marker on the dashboard's plot.

Payload estimation: at rest, the torque a joint's servo exerts beyond what the DT's model needs is the
payload's weight through the tool's Jacobian, tau - tau0(q) = m * phi(q) with phi = -J(q)^T g (per kg);
tau0 is the DT's own torque at the same time (both at rest) less that of the payload it was given, so
whatever else both carry (a grasped object) cancels.
Least squares over every rest sample (each a vector of joint torques) gives m and, from the residuals, its
standard deviation; once that is below `payload_std` the DT's payload body (a point mass at the tool
frame, as `cotwin plant` adds one) takes the mass, recorded as a correction too.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from ...diagnostics import CotwinError, Finding, Severity
from .observing import TwinObserver
from ..project.sections import Convergence as ConvergenceSettings

log = logging.getLogger("cotwin.twin")

PLACEHOLDER_KG = 1e-6  # the DT's payload body is built with this mass, set to 0 before the run starts
PRIOR_KG = 1000.0  # the estimate's prior standard deviation: nothing known (cotwin.pmodel.perturbation.MAX_PAYLOAD)

# [convergence]'s settings are a section of the project (cotwin.twin.project.sections.Convergence)


# ---- the DT ---------------------------------------------------------------------------------------------

def estimates_payload(spec) -> bool:
    """Whether the project's DT needs a payload body ([convergence] estimate = "payload")."""
    settings = spec.convergence
    return settings is not None and settings.estimate == "payload"


def payload_simulator(tree, scene, base: str = "fixed", timestep: float | None = None, tool=None):
    """The embedded simulator with a payload body at the tool (the project's `tool`, cotwin.pmodel.perturbation.
    with_payload) of no
    mass until an estimate is applied: the DT of a twin estimating its payload, and its what-if forks (a
    saved state holds every body's pose, so the fork's model must have the same bodies)."""
    from ...pmodel.mjcf import TIMESTEP, to_mjcf
    from ...pmodel.perturbation import PAYLOAD_BODY, with_payload
    from ...pmodel.simulator import PlatformSimulator

    timestep = TIMESTEP if timestep is None else timestep
    xml = with_payload(to_mjcf(tree, scene, timestep, visual=False, base=base), tree, PLACEHOLDER_KG, base, tool)
    sim = PlatformSimulator(tree, scene, timestep, mjcf=xml, base=base)
    body = sim.model.body(PAYLOAD_BODY).id
    sim.model.body_mass[body] = 0.0
    sim.model.body_inertia[body] = 0.0
    sim.reset()
    return sim


# ---- payload estimation -----------------------------------------------------------------------------------

class PayloadEstimator:
    """Least squares of the payload mass from joint torques at rest (see the module doc), on a scratch copy
    of the DT's MuJoCo data (the DT's own state is never touched)."""

    def __init__(self, sim, effort_sensors: dict[str, str]):
        import mujoco

        from ...pmodel.perturbation import PAYLOAD_BODY

        self.sim = sim
        self.model = sim.model
        self.data = mujoco.MjData(sim.model)
        self.body = sim.model.body(PAYLOAD_BODY).id
        self.sensors = effort_sensors  # joint -> the PT's reading of its torque (by mapping path)
        self.joints = list(effort_sensors)
        self.qpos = {j: sim.model.joint(j).qposadr[0] for j in sim.joint_names}
        self.dofs = np.array([sim.model.joint(j).dofadr[0] for j in self.joints], dtype=int)
        self.sum_pp = 0.0  # sum of phi . phi
        self.sum_pr = 0.0  # sum of phi . r
        self.sum_rr = 0.0
        self.count = 0  # scalar measurements (joint torques) taken
        self.samples = 0  # rest samples taken

    def regressor(self, positions: dict[str, float]) -> tuple[np.ndarray, np.ndarray]:
        """(tau0, phi) at these joint positions: the torques the DT's model needs at rest without the
        payload, and those one kilogram at the payload body adds."""
        import mujoco

        model, data = self.model, self.data
        mass = float(model.body_mass[self.body])
        data.qpos[:] = model.qpos0
        for name, value in positions.items():
            if name in self.qpos:
                data.qpos[self.qpos[name]] = value
        data.qvel[:] = 0.0
        data.qacc[:] = 0.0
        mujoco.mj_inverse(model, data)
        jacp = np.zeros((3, model.nv))
        mujoco.mj_jacBody(model, data, jacp, None, self.body)
        phi = -(jacp.T @ model.opt.gravity)[self.dofs]
        tau = data.qfrc_inverse[self.dofs] - mass * phi
        return tau, phi

    def torques(self, readings: dict[str, float]) -> np.ndarray | None:
        measured = [readings.get(self.sensors[j]) for j in self.joints]
        if any(v is None or not math.isfinite(v) for v in measured):
            return None
        return np.asarray(measured, dtype=float)

    def observe(self, positions: dict[str, float], readings: dict[str, float], reference=None) -> bool:
        """Take one rest sample (PT joint positions, PT sensor readings); False when a torque is missing.
        `reference`: the DT's (joint positions, sensor readings) at the same time: its torques less its own
        payload's are then what the model needs there, so that whatever else both carry (a grasped object, an
        arm's weight its servos hold) cancels; without it, MuJoCo's inverse dynamics at rest."""
        measured = self.torques(readings)
        if measured is None:
            return False
        tau0, phi = self.regressor(positions)
        if reference is not None:
            modelled = self.torques(reference[1])
            if modelled is None:
                return False
            tau0 = modelled - float(self.model.body_mass[self.body]) * self.regressor(reference[0])[1]
        r = measured - tau0
        self.sum_pp += float(phi @ phi)
        self.sum_pr += float(phi @ r)
        self.sum_rr += float(r @ r)
        self.count += len(r)
        self.samples += 1
        return True

    @property
    def mass(self) -> float | None:
        return self.sum_pr / self.sum_pp if self.sum_pp > 0 else None

    @property
    def std(self) -> float:
        """The estimate's standard deviation (kg): residual variance over the information taken."""
        if self.sum_pp <= 0 or self.count < 2:
            return PRIOR_KG
        m = self.sum_pr / self.sum_pp
        residual = max(0.0, self.sum_rr - 2 * m * self.sum_pr + m * m * self.sum_pp)
        return math.sqrt(residual / (self.count - 1) / self.sum_pp)

    def apply(self, mass: float) -> None:
        """The DT's payload body takes `mass` (kg), a solid sphere as `cotwin plant` makes it."""
        from ...pmodel.perturbation import PAYLOAD_RADIUS

        self.model.body_mass[self.body] = mass
        self.model.body_inertia[self.body] = 0.4 * mass * PAYLOAD_RADIUS ** 2


def effort_sensors(tree) -> dict[str, str]:
    """Joint -> the mapping path of the p-model sensor reading its torque (or force), for actuated joints."""
    from ...pmodel.tree import reading_path

    actuated = {j.name for j in tree.actuated}
    out = {}
    for s in tree.sensors:
        if s.quantity == "effort" and s.joint in actuated:
            out.setdefault(s.joint, reading_path(tree.name, s))
    return out


# ---- the service ----------------------------------------------------------------------------------------

class Convergence(TwinObserver):
    """A live twin's observer that resyncs the DT and estimates the payload (see the module doc). It runs
    first among the observers, after the step's deviation check and history record."""

    def __init__(self, settings: ConvergenceSettings, system, history=None):
        self.settings = settings
        self.spec = spec = system.spec
        self.tree = system.models.tree
        if spec.endpoint != "mujoco":
            raise CotwinError([Finding(spec.location("convergence"), Severity.ERROR, "[convergence] corrects a DT in the "
                                       f"embedded simulator, not a robot behind the broker ([platform] endpoint = "
                                       f"\"{spec.endpoint}\")")])
        at = spec.location("convergence", "estimate")
        if settings.estimate == "payload" and not effort_sensors(self.tree):
            raise CotwinError([Finding(at, Severity.ERROR, f"[convergence] estimate = \"payload\": p-model "
                                                           f"{self.tree.name} has no sensor of a joint's torque (effort) "
                                                           "to estimate it from")])
        if settings.estimate == "payload" and spec.pt is not None and spec.pt.endpoint == "replay":
            raise CotwinError([Finding(at, Severity.ERROR, "[convergence] estimate = \"payload\" needs a PT reporting "
                                                           "joint torques; a replayed log reports positions and "
                                                           "velocities only")])
        self.history = history
        self.events: list[dict] = []  # every correction, as recorded
        self.estimator: PayloadEstimator | None = None
        self.applied: float | None = None
        self.trace: list[tuple[float, float, float]] = []  # (time, estimate, std) whenever a sample was taken
        self._seen_alarms = 0
        self._rested = False  # the PT was at rest at the previous step

    # ---- start ----
    def twin_started(self, twin) -> None:
        self.pt = twin.sides["pt"].units["mapping"].mapping.endpoint
        self.dt_mapping = twin.sides["dt"].units["mapping"].mapping
        self.dt = self.dt_mapping.endpoint
        self.monitor = twin.monitor
        self._seen_alarms = len(self.monitor.events)
        from ...mapping.endpoint import SimulatedEndpoint

        if not isinstance(self.dt, SimulatedEndpoint):
            raise CotwinError([Finding(self.spec.location("convergence"), Severity.ERROR,
                                       "[convergence] corrects a DT in the embedded simulator ([platform] endpoint = "
                                       f"\"mujoco\"), not a {type(self.dt).__name__}")])
        if self.settings.estimate == "payload":
            self.estimator = self._estimator()

    def _estimator(self) -> PayloadEstimator:
        from ...pmodel.perturbation import PAYLOAD_BODY

        at = self.spec.location("convergence", "estimate")
        try:
            self.dt.sim.model.body(PAYLOAD_BODY)
        except KeyError:
            raise CotwinError([Finding(at, Severity.ERROR, "[convergence] estimate = \"payload\": the DT has no payload "
                                                           "body at its tool (cotwin.twin.assembly.convergence."
                                                           "payload_simulator builds one)")]) from None
        return PayloadEstimator(self.dt.sim, effort_sensors(self.tree))

    # ---- each step ----
    def twin_step(self, twin, k: int, t: float) -> None:
        if self.estimator is not None:
            self._estimate(k, t)
        reason = self._resync_reason(k)
        if reason is not None:
            self.resync(k, t, reason)

    def _resync_reason(self, k: int) -> str | None:
        mode = self.settings.mode
        raised = [e["variable"] for e in self.monitor.events[self._seen_alarms:] if e["state"] == "raised"]
        self._seen_alarms = len(self.monitor.events)
        if mode == "every":
            return f"every {self.settings.every} steps" if k % self.settings.every == 0 else None
        if mode == "on-alarm":
            names = list(dict.fromkeys([*raised, *self.monitor.active]))
            return f"alarm: {', '.join(names)}" if names else None
        return None

    def resync(self, k: int, t: float, reason: str) -> dict:
        """Put the PT's measured joint state into the DT now; the correction, recorded."""
        q, qd = self.pt.joint_positions(), self.pt.joint_velocities()
        before, speeds = self.dt.joint_positions(), self.dt.joint_velocities()
        size = max((abs(q[j] - before[j]) for j in q if j in before), default=0.0)
        speed = max((abs(qd[j] - speeds[j]) for j in qd if j in speeds), default=0.0)
        self.dt.resync(q, qd)
        self.dt_mapping.step(0.0)  # the mapping reads the new state (no time passes)
        return self._record({"kind": "resync", "step": k, "time": t, "reason": reason, "size": size,
                             "detail": {"velocity": speed, "joints": len(q)}})

    def _estimate(self, k: int, t: float) -> None:
        estimator, settings = self.estimator, self.settings
        speeds = [*self.pt.joint_velocities().values(), *self.dt.joint_velocities().values()]
        rest, self._rested = self._rested, bool(speeds) and all(abs(v) <= settings.rest_speed for v in speeds)
        if not (rest and self._rested):  # both at rest at this step and the one before: settled, no inertial torque
            return
        reference = (self.dt.joint_positions(), self.dt.read_sensors())
        if not estimator.observe(self.pt.joint_positions(), self.pt.read_sensors(), reference):
            return
        mass, std = estimator.mass, estimator.std
        self.trace.append((t, mass, std))
        if std > settings.payload_std or mass is None:
            return
        mass = max(0.0, mass)
        if self.applied is not None and abs(mass - self.applied) <= std:
            return  # what the DT has is within the estimate's uncertainty
        previous = self.applied or 0.0
        estimator.apply(mass)
        self.applied = mass
        self._record({"kind": "payload", "step": k, "time": t, "reason": f"estimate {mass:.4g} kg +- {std:.2g} kg",
                      "size": mass - previous, "detail": {"mass": mass, "std": std, "samples": estimator.samples}})

    def _record(self, event: dict) -> dict:
        event = {"type": "correction", "twin": self.spec.path.stem, **event}
        self.events.append(event)
        log.info("DT corrected (%s) at t = %.3f s: %s, size %.4g", event["kind"], event["time"], event["reason"],
                 event["size"])
        if self.history is not None:
            self.history.record_correction(event)
        return event

    def report(self) -> dict:
        resyncs = [e for e in self.events if e["kind"] == "resync"]
        out = {"settings": self.settings.as_dict(), "resyncs": len(resyncs),
               "largest_resync": max((e["size"] for e in resyncs), default=None), "corrections": list(self.events)}
        if self.estimator is not None:
            out["payload"] = {"estimate": self.estimator.mass, "std": self.estimator.std,
                              "samples": self.estimator.samples, "applied": self.applied}
        return out


def summary(report: dict) -> str:
    """One line for the command line: the resyncs and the payload estimate of a run's convergence report."""
    text = f"convergence: {report['resyncs']} resync(s)"
    if report["largest_resync"] is not None:
        text += f" (largest {report['largest_resync']:.4g})"
    payload = report.get("payload")
    if payload is not None:
        if payload["estimate"] is None:
            text += "; payload: no rest sample of the PT to estimate it from"
        else:
            applied = f"applied {payload['applied']:.4g} kg" if payload["applied"] is not None else "not confident enough to apply"
            text += (f"; payload {payload['estimate']:.4g} +- {payload['std']:.2g} kg from {payload['samples']} rest "
                     f"sample(s), {applied}")
    return text
