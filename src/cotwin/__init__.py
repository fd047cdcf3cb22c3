"""cotwin: RoboSim models to FMI-based digital twins."""

__version__ = "0.1.0"
