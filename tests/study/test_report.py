"""The study report (dualarm.study.report) on a hand-made trials table whose rates are known: the Wilson intervals
against their closed form, the binned rates against counts made here, and the logistic fit against the model the
table was drawn from."""

import math

import numpy as np
import pandas as pd
import pytest

from dualarm.errors import OutputError, RecordingError
from dualarm.record.run_dir import claim_output_dir
from dualarm.study.report import feature_rates, logistic_fit, method_rates, read_trials, write_study_report
from tests.helpers import dualarm_subprocess

Z95 = 1.959963984540054  # the normal distribution's 97.5 % quantile


def wilson_closed_form(k: int, n: int) -> tuple[float, float]:
    """Wilson (1927): (p + z^2/2n -+ z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n)."""
    p = k / n
    centre, half = p + Z95**2 / (2 * n), Z95 * math.sqrt(p * (1 - p) / n + Z95**2 / (4 * n * n))
    return (centre - half) / (1 + Z95**2 / n), (centre + half) / (1 + Z95**2 / n)


def hand_made() -> pd.DataFrame:
    """Method `a`: 2000 trials, P(inconsistent) = logistic(-1 + (size - 0.1) / 0.03) (one unit per 0.03 m), P(failed) 0;
    method `b`: 200 trials, the first 30 inconsistent (of them 10 failed), 12 violated (50-61), plus 5 rows that are
    errors; kinds cycle."""
    rng = np.random.default_rng(7)
    size = rng.normal(0.1, 0.03, 2000)
    a = pd.DataFrame(
        {
            "method": "a",
            "trial": np.arange(2000),
            "size_m": size,
            "kind": np.array(["circle", "polygon"])[np.arange(2000) % 2],
        }
    )
    a["inconsistent"] = rng.random(2000) < 1 / (1 + np.exp(-(-1 + (size - 0.1) / 0.03)))
    a["failed"] = False
    b = pd.DataFrame(
        {
            "method": "b",
            "trial": np.arange(205),
            "size_m": rng.uniform(0.05, 0.15, 205),
            "kind": np.array(["circle", "polygon"])[np.arange(205) % 2],
        }
    )
    b["inconsistent"] = np.arange(205) < 30
    b["failed"] = np.arange(205) < 10
    rows = pd.concat([a, b], ignore_index=True)
    rows["status"] = "complete"
    rows.loc[(rows["method"] == "b") & (rows["trial"] >= 200), "status"] = "error"
    rows.loc[(rows["method"] == "b") & (rows["trial"] >= 50) & (rows["trial"] < 62), "status"] = "violated"
    rows["study"] = "hand-made"
    return rows


def test_per_method_rates_and_wilson_intervals():
    rates = method_rates(hand_made()).set_index("method")
    b = rates.loc["b"]
    assert (b["trials"], b["errors"], b["inconsistent"], b["failed"], b["violated"]) == (200, 5, 30, 10, 12)
    assert rates.loc["a", "violated"] == 0
    assert b["p_inconsistent"] == 30 / 200
    np.testing.assert_allclose(
        (b["p_inconsistent_low"], b["p_inconsistent_high"]), wilson_closed_form(30, 200), rtol=1e-12
    )
    np.testing.assert_allclose((b["p_failed_low"], b["p_failed_high"]), wilson_closed_form(10, 200), rtol=1e-12)
    a = rates.loc["a"]
    assert a["p_failed"] == 0
    np.testing.assert_allclose(
        (a["p_failed_low"], a["p_failed_high"]), wilson_closed_form(0, 2000), rtol=1e-12, atol=1e-15
    )


def test_binned_rates_are_the_counts_per_bin():
    rows = hand_made()
    table = feature_rates(rows)
    kinds = table[(table["feature"] == "kind") & (table["method"] == "b")].set_index("bin")
    judged = rows[(rows["method"] == "b") & (rows["status"] != "error")]
    for kind in ("circle", "polygon"):
        mine = judged[judged["kind"] == kind]
        assert (kinds.loc[kind, "trials"], kinds.loc[kind, "inconsistent"]) == (
            len(mine),
            int(mine["inconsistent"].sum()),
        )
        np.testing.assert_allclose(
            (kinds.loc[kind, "low"], kinds.loc[kind, "high"]),
            wilson_closed_form(int(mine["inconsistent"].sum()), len(mine)),
            rtol=1e-12,
        )
    sizes = table[(table["feature"] == "size_m") & (table["method"] == "a")].sort_values("bin_order")
    assert (
        len(sizes) == 4 and sizes["trials"].sum() == 2000 and abs(sizes["trials"] - 500).max() <= 25
    )  # quartiles of both methods' sizes
    assert sizes["p_inconsistent"].is_monotonic_increasing  # the model's rate rises with size


def test_the_logistic_fit_finds_the_model_the_table_was_drawn_from():
    rows = hand_made()
    fit, skipped = logistic_fit(rows)
    a = fit[(fit["method"] == "a") & (fit["feature"] == "size_m")].iloc[0]
    sd = rows.loc[rows["method"] == "a", "size_m"].std()
    truth = math.exp(sd / 0.03)  # the model's odds ratio per standard deviation of the sample
    assert a["low"] < truth < a["high"] and a["p_value"] < 1e-6
    assert set(fit["method"]) == {"a", "b"} and not skipped


def test_a_method_whose_trials_all_agree_has_no_fit_and_says_why():
    rows = hand_made()
    rows.loc[rows["method"] == "b", "inconsistent"] = True
    fit, skipped = logistic_fit(rows)
    assert set(fit["method"]) == {"a"} and skipped == {"b": "all 200 trials inconsistent"}


def test_the_report_is_written_from_trials_parquet_alone(tmp_path):
    out = tmp_path / "study"
    with claim_output_dir(out, "study"):
        hand_made().to_parquet(out / "trials.parquet")
    report = write_study_report(out)
    text = report.read_text()
    low, high = wilson_closed_form(30, 200)
    assert f"0.150 [{low:.3f}, {high:.3f}]" in text
    for name in ("methods.csv", "features.csv", "logit.csv", "methods.png", "features.png"):
        assert (out / name).stat().st_size > 0
    pd.testing.assert_frame_equal(pd.read_csv(out / "methods.csv"), method_rates(read_trials(out)), check_dtype=False)


def test_a_report_replaces_its_own_files_but_never_a_users(tmp_path):
    """Written twice, the report replaces its own files; a report.md the user wrote (or edited) is refused in one line
    naming it, byte for byte kept, and nothing else is written (it was overwritten, exit 0)."""
    out = tmp_path / "study"
    with claim_output_dir(out, "study"):
        hand_made().to_parquet(out / "trials.parquet")
    first = write_study_report(out).read_text()
    assert write_study_report(out).read_text() == first
    (out / "report.md").write_text("my notes on this study\n")
    (out / "methods.csv").unlink()
    with pytest.raises(OutputError, match=r"report\.md: not the file the last 'study report' wrote there") as raised:
        write_study_report(out)
    assert "\n" not in str(raised.value)
    assert (out / "report.md").read_text() == "my notes on this study\n" and not (out / "methods.csv").exists()


@pytest.mark.parametrize(
    ("change", "why"),
    [
        (lambda rows: rows.iloc[:0], "no rows"),  # KeyError 'p_inconsistent'
        (
            lambda rows: rows.assign(inconsistent=rows["inconsistent"].astype(str)),
            "column inconsistent holds .*, not booleans",
        ),
    ],
)
def test_a_table_without_rows_or_with_verdicts_as_text_is_one_line(tmp_path, change, why):
    out = tmp_path / "study"
    with claim_output_dir(out, "study"):
        change(hand_made()).to_parquet(out / "trials.parquet")
    with pytest.raises(RecordingError, match=why) as raised:
        write_study_report(out)
    assert "\n" not in str(raised.value) and not (out / "report.md").exists()


@pytest.mark.integration
def test_a_report_without_a_table_is_one_line(tmp_path):
    with pytest.raises(RecordingError, match="no such file"):
        write_study_report(tmp_path)
    done = dualarm_subprocess(["study", "report", str(tmp_path / "none")], 120)
    assert done.returncode == 2 and done.stderr.count("\n") == 1 and "trials.parquet: no such file" in done.stderr
