"""The ``dualarm`` command line (Typer).

User mistakes (a malformed task file, an unknown robot, a corrupt recording, an argument outside
its range, an output directory holding files dualarm did not write, ...) print one line on
stderr and exit with code 2; no traceback. Every argument is checked before any work. Messages
are printed as they are (no markup, no emoji codes) and quote at most about 80 characters of a
user's string (:func:`dualarm.errors.excerpt`); a line is cut at :data:`MAX_LINE` characters.

Exit codes (:data:`EXIT_CODES`): 0 complete, 3 violated (the run finished, but a check failed),
1 failed, 2 a user's mistake, 130 interrupted by Ctrl-C (SIGINT), 143 terminated (SIGTERM). An
interrupted run is kept as failed, as any run that stops half-way.

A module per command group: :mod:`.run` (run, plan), :mod:`.reproduce`, :mod:`.runs` (inspect, view,
report, compare), :mod:`.study` (consistency, study), :mod:`.bench`, :mod:`.ik`, :mod:`.task`,
:mod:`.robot`; the app, its errors and signals in :mod:`.app`, argument checks in :mod:`.options`.
"""

# Each command module registers its commands on the app when imported: help lists them in this order.
# isort: off
from dualarm.cli import run, reproduce, runs, study, robot, bench, ik, task  # noqa: F401

# isort: on
from dualarm.cli.app import app

__all__ = ["app"]
