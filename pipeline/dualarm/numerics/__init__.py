"""Numerics: CasADi Functions compiled to machine code and evaluated many inputs per call.

Compiled: :mod:`.compiled`; many inputs per call: :mod:`.batched`.
"""
