"""``dualarm reproduce``: every experiment of the three papers, run, recorded and set against them.

Set against the papers' figures.
"""
