"""A fuzz of study specs (Hypothesis): the shipped ``studies/inconsistency.toml``, its keys deleted or set to anything.

Each example sets up to four keys (top level or in a table, known or not) to a value of any TOML type: numbers with
NaN and the infinities, huge and negative ones, strings with a NUL or 10,000 characters, lists, tables; or deletes
one. The spec is then read as ``dualarm study`` reads it, and a spec that validates has its first trials drawn. Either
it validates and draws, or it is refused in one line naming the key (``TaskFileError``); never another exception.
The command line's own handling of that error (one line, exit 2) is tested in ``test_run.py``.
"""

from __future__ import annotations

import tomllib

import tomli_w
from hypothesis import given, settings
from hypothesis import strategies as st

from dualarm.errors import DualarmError, TaskFileError
from dualarm.study.spec import study_from_toml
from dualarm.study.trials import trial
from tests.helpers import REPO

SPEC = tomllib.loads((REPO / "studies" / "inconsistency.toml").read_text())
TABLES = [key for key, value in SPEC.items() if isinstance(value, dict)]
KEYS = [(None, key) for key in SPEC] + [(table, key) for table in TABLES for key in SPEC[table]] + [(None, "colour")]

scalar = st.one_of(
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, -1, 1, 10**6, 10**7, 0.0, 1e308, -1e-308]),
    st.text(max_size=20),
    st.sampled_from(["", "\0", "a" * 10_000, "humanoid\0", "../../etc", "mc-inverse", "left", "polygon"]),
    st.booleans(),
)
value = st.one_of(scalar, st.lists(scalar, max_size=4), st.dictionaries(st.text(max_size=8), scalar, max_size=3))


@settings(max_examples=300, deadline=None, derandomize=True)
@given(st.lists(st.tuples(st.sampled_from(KEYS), st.one_of(st.none(), value)), min_size=1, max_size=4))
def test_a_mutated_spec_validates_and_draws_or_is_one_line(changes):
    spec = {k: dict(v) if isinstance(v, dict) else v for k, v in SPEC.items()}
    for (table, key), new in changes:
        where = spec if table is None else spec.setdefault(table, {})
        if not isinstance(where, dict):
            continue
        if new is None:
            where.pop(key, None)
        else:
            where[key] = new
    try:
        loaded = study_from_toml(tomli_w.dumps(spec), "spec.toml")
    except TaskFileError as error:
        assert "\n" not in str(error) and str(error).startswith("spec.toml"), (changes, str(error))
        return
    try:
        for index in range(min(loaded.trials, 3)):
            trial(loaded, index)
    except DualarmError as error:  # a draw that cannot be made is the user's to hear about, in one line
        assert "\n" not in str(error), (changes, str(error))
