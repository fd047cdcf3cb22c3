"""The live twin: PT and DT in lockstep (`runtime`), the services as its observers (`live_observers`),
a cell's live twin (`cell_live`). Imports the twin's project, assembly and services parts."""
