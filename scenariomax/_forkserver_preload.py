"""Imported by the conversion's fork server when it starts: the server dies with the main process.

Otherwise a main process killed with SIGKILL leaves the server (and workers blocked on its pipes) behind.
"""

from scenariomax._lifeline import exit_with_parent

exit_with_parent()
