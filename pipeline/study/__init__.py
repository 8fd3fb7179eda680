"""``dualarm study``: the MC-Inverse paper's open question, when and how often motion becomes inconsistent, over many generated trials.

Modules:

- :mod:`dualarm.study.spec`: the study spec file (:class:`StudySpec`, :func:`load_study`).
- :mod:`dualarm.study.trials`: the trials it draws (:func:`trial`), the same on any machine.
"""

from dualarm.study.spec import StudySpec, load_study
from dualarm.study.trials import Trial, trial

__all__ = ["StudySpec", "Trial", "load_study", "trial"]
