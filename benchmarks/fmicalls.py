"""The same work for both peers: cotwin's FMU units through fmi2Set/Get/DoStep calls only."""

from __future__ import annotations

from cotwin.cosim.units import FMUUnit


class FMICallsOnly:
    """Within the block, FMU units made then talk to their FMU through FMI calls only: the in-memory port
    path of cotwin-built FMUs (`cotwin_ports`, which writes inputs straight into the C model's arrays)
    is switched off, so that a figure said to be through FMI calls is, and a third-party master's peer
    figure does the same work."""

    def __enter__(self):
        self._memory = FMUUnit._port_memory
        FMUUnit._port_memory = lambda unit: None
        return self

    def __exit__(self, *exc):
        FMUUnit._port_memory = self._memory
