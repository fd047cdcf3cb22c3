"""The twin's live web dashboard (`cotwin run|twin --dashboard HOST:PORT`): PT and DT joint angles with
deviation alarms, the d-model's state machines with the active state, the robot in 3D from the
p-model's geometry, a command panel publishing on the twin's broker, and the history store.

describe.py derives what the page draws from the models, feed.py is the observer the twin writes to,
commands.py publishes the panel's commands, app.py serves it all (static/ holds the page and the
vendored three.js).
"""

from .app import Dashboard, parse_address

__all__ = ["Dashboard", "parse_address"]
