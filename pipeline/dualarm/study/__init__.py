"""``dualarm study``: the MC-Inverse paper's open question, over many generated trials.

The question: when and how often motion becomes inconsistent.

Modules:

- :mod:`dualarm.study.spec`: the study spec file (:class:`StudySpec`, :func:`load_study`).
- :mod:`dualarm.study.trials`: the trials it draws (:func:`trial`, :func:`reachable_trial`), the same on any machine.
- :mod:`dualarm.study.run`: running them on Dask distributed (:func:`run_study`), the rows as they
  come (:func:`read_study`).
- :mod:`dualarm.study.report`: P(inconsistent) per method and condition from ``trials.parquet``
  (:func:`write_study_report`).
"""

from dualarm.study.report import write_study_report
from dualarm.study.run import read_study, run_study
from dualarm.study.spec import StudySpec, load_study
from dualarm.study.trials import Trial, reachable_trial, trial

__all__ = [
    "StudySpec",
    "Trial",
    "load_study",
    "reachable_trial",
    "read_study",
    "run_study",
    "trial",
    "write_study_report",
]
