"""A robot's description as dualarm reads it.

``dualarm robot init`` (:mod:`.init`) and ``dualarm robot check`` (:mod:`.check`).
"""
