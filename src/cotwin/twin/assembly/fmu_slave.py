"""The one pythonfmu slave behind cotwin's Python FMUs (the platform mapping and the command sources).

pythonfmu packages this file; at instantiation the slave reads `cotwin_unit.json` from its resources
(the unit's role and the twin project copied beside it), rebuilds that cotwin unit and exposes its
ports. The same class serves every role, so no per-unit template exists.

FMU states (fmi2GetFMUstate, fmi2SerializeFMUstate and their inverses) are the unit's own state
(`Unit.get_state`: the mapping runtime's variables, the simulator, the trajectory in flight), which
pythonfmu carries as JSON: the bytes go base64-encoded.
"""

import base64
import json
from pathlib import Path

from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Integer, Real

_TYPES = {"Boolean": Boolean, "Integer": Integer, "Real": Real}


class CotwinUnit(Fmi2Slave):
    author = "cotwin"
    description = "a cotwin co-simulation unit (platform mapping or command source)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        from cotwin.twin.assembly.run import python_unit

        config = json.loads((Path(self.resources) / "cotwin_unit.json").read_text())
        self.unit = python_unit(Path(self.resources) / config["project"], config["role"], self.instance_name)
        self.start_time = 0.0
        for port in self.unit.ports.values():
            is_input = port.causality == "input"
            # outputs start with the unit's initial values (exact), so they need no initial unknowns
            self.register_variable(_TYPES[port.type](
                port.name, causality=Fmi2Causality.input if is_input else Fmi2Causality.output,
                variability=Fmi2Variability.discrete, initial=None if is_input else Fmi2Initial.exact,
                getter=lambda n=port.name: self.unit.values[n],
                setter=lambda v, n=port.name: self.unit.set({n: v})))

    def setup_experiment(self, start_time, stop_time, tolerance):
        self.start_time = start_time

    def enter_initialization_mode(self):
        self.unit.instantiate(self.start_time)  # connects to the platform or broker: not when described

    def exit_initialization_mode(self):
        self.unit.initialize()

    def do_step(self, current_time, step_size):
        self.unit.step(current_time, step_size)
        return True

    def terminate(self):
        self.unit.terminate()

    # pythonfmu's hooks behind canGetAndSetFMUstate and canSerializeFMUstate
    def _get_fmu_state(self):
        return {"cotwin": base64.b64encode(self.unit.get_state()).decode("ascii")}

    def _set_fmu_state(self, state):
        self.unit.set_state(base64.b64decode(state["cotwin"]))
