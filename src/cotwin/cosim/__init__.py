"""Co-simulation: units (FMUs via FMPy, in-process Python), the master, scenarios, multimodels."""
