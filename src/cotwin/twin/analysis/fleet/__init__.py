"""Fleets of twins (`cotwin fleet`): many live twins run together on Ray (or in one process), one history
store, per-twin alarms, an overview page and a supervisor restarting a failed twin from its saved state."""
