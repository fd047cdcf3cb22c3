"""The twin layer: a project's models assembled into a co-simulation, run as a digital twin beside its
physical twin, with the services and analyses around it. It may import every cotwin package below it
(robosim, dmodel, pmodel, mapping, cosim); inside it, each part imports only its own and those before
it in PARTS, each part a subpackage (tests/test_layering.py checks both, import by import):

- project (a subpackage): the project file's schema (`project.sections`), reading, overrides and
  writing (`project.load`, all exported by `cotwin.twin.project`), its reference (`project.doc`).
  Imports nothing else of the twin.
- assembly: scenarios and command sources (`scenario`, `commands`, `replay`, `rabbitmq`), the models
  and units of a twin (`system`, `mapping_unit`, `calibration`), artefacts (`build`, `fmu_slave`),
  one co-simulated run (`run`, `clocked`, `waits`, `outcomes`), the PT's and DT's platform endpoints by kind
  (`endpoints`), what watches a live twin (`observing`), a cell of several robots (`cell`), broker accounts
  (`broker_access`).
- services: what runs beside a twin: deviation, history, what-if, the publisher, the OPC UA plant,
  the page (`dashboard`).
- live: the live twin, PT and DT in lockstep (`runtime`), its services as its observers (`live_observers`);
  that of a cell of several robots (`cell_live`).
- analysis: many runs or runs judged: sweeps (`sweep`, its scratch folder `scratch`, its threads against the
  machine `thread_budget`), generated tests run on a twin, walks, fleets of live twins (`fleet`: on Ray,
  supervised, with an overview page).
"""

PARTS: dict[str, tuple[str, ...]] = {
    "project": ("project",),
    "assembly": ("commands", "scenario", "replay", "calibration", "rabbitmq", "mapping_unit", "system", "build",
                 "fmu_slave", "outcomes", "waits", "clocked", "observing", "convergence", "cell", "run", "endpoints",
                 "broker_access"),
    "services": ("deviation", "history", "whatif", "publisher", "plant", "dashboard"),
    "live": ("live_observers", "runtime", "cell_live"),
    "analysis": ("sweep", "scratch", "thread_budget", "testing", "walks", "fleet"),
}
