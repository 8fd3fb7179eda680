"""The report's figures on what robots other than the humanoid record."""

import numpy as np
import pandas as pd

from dualarm.report.figures import joints_against_bounds


def test_a_joint_without_limits_is_drawn_against_its_values(tmp_path):
    """A continuous joint's bounds are recorded as infinite or missing (NaN: a PR2's wrist roll): the figure is
    written, each axis spanning the joint's values (reproduce --robot PR2 ended in 'Axis limits cannot be NaN or
    Inf')."""
    import matplotlib.pyplot as plt

    t = np.linspace(0.0, 1.0, 11)
    sample = pd.DataFrame({"t": t, "position.roll": np.sin(3 * t), "position.flex": t - 0.5})
    bounds = pd.DataFrame(
        {
            "t": t,
            "theta_lower.roll": np.full(11, -np.inf),
            "theta_upper.roll": np.full(11, np.nan),
            "theta_lower.flex": np.full(11, -1.0),
            "theta_upper.flex": np.full(11, 1.0),
        }
    )
    seen = []
    savefig = plt.Figure.savefig

    def keep(fig, *args, **kwargs):
        seen.extend(ax.get_ylim() for ax in fig.axes if ax.get_visible())
        return savefig(fig, *args, **kwargs)

    plt.Figure.savefig = keep
    try:
        path = joints_against_bounds(sample, bounds, "position", "test", tmp_path / "joints.png")
    finally:
        plt.Figure.savefig = savefig
    assert path.is_file() and path.stat().st_size > 0
    for (low, high), column in zip(seen, ["roll", "flex"], strict=True):
        values = sample[f"position.{column}"]
        assert np.isfinite([low, high]).all() and low < values.min() and high > values.max()
