"""Numerics: CasADi Functions compiled to machine code (:mod:`.compiled`) and evaluated many inputs per call (:mod:`.batched`)."""
