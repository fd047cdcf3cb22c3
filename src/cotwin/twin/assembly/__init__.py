"""The twin's assembly: a project's models made into one co-simulation (the TwinSystem, its units and
connections, a cell of several robots), its command sources, its artefacts, the PT's and DT's endpoints
by kind, and one co-simulated run. Imports cotwin.twin.project and the layers below the twin only."""
