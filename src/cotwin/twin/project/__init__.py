"""A twin project (`cotwin.toml`), the project part of the twin layer: its schema (`sections`: one typed
dataclass per table), reading, overrides and writing (`load`), and its reference docs/project.md
generated from the schema (`doc`: `python -m cotwin.twin.project.doc`). Imports no other part of
cotwin.twin.
"""

from .load import (PT_KEYS, PTSettings, TwinProject, load_project, override_path,  # noqa: F401
                   pt_url_problem)
from .sections import (AMQP_MAX, CYCLE_PERIOD, ENDPOINTS, MAX_CYCLES_PER_STEP, MAX_LAG_STEPS,  # noqa: F401
                       MAX_WAIT_S, PT_ENDPOINTS, SECTIONS, SHAPES, STAND_IN_EXTENT, URL, DeviationSettings,
                       ProjectSettings, RabbitMQSettings, amqp_name_problem, check_timing, cycle_period,
                       cycle_time_warnings,
                       history_url_problem, project_settings, routing_key_problem, run_timing_message,
                       timing_problems)

__all__ = ["PT_KEYS", "PTSettings", "TwinProject", "load_project", "override_path", "pt_url_problem", "AMQP_MAX",
           "CYCLE_PERIOD", "ENDPOINTS", "MAX_CYCLES_PER_STEP", "MAX_LAG_STEPS", "MAX_WAIT_S", "PT_ENDPOINTS",
           "SECTIONS", "SHAPES", "STAND_IN_EXTENT", "URL", "DeviationSettings", "ProjectSettings",
           "RabbitMQSettings", "amqp_name_problem", "check_timing", "cycle_period", "cycle_time_warnings", "history_url_problem", "project_settings",
           "routing_key_problem", "run_timing_message", "timing_problems"]
