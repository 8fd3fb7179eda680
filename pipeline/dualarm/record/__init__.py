"""Recording runs (MCAP + Rerun + manifest + metrics) and reading them back into pandas."""
