"""The RoboSim front end: grammars, parser, typed model, name and type resolution."""
