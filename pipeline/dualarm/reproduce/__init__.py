"""``dualarm reproduce``: every experiment of the three papers, run, recorded and set against the papers' figures."""
