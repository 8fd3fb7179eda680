"""CasADi Functions compiled to machine code, kept on disk between processes.

CasADi evaluates an SX Function in its own virtual machine. The same Function written out as C by
CasADi's code generator and built by the system's C compiler computes the same operations about
three times faster (``dualarm bench ik`` shows both). :func:`compiled` builds that shared library
once and loads it with ``casadi.external``; the library is kept under :func:`cache_dir`, named by
the SHA-256 of its C source and the compiler's command, so a later process (a study's worker, the
next ``dualarm run``) loads it in about a millisecond instead of compiling for half a second.

The compiler runs with ``-O2 -ffp-contract=off``: no fused multiply-add and no reordering, so the
library performs the virtual machine's floating-point operations in its order and gives the same
results bit for bit (the tests compare both on random inputs). Where there is no C compiler
(``$CC``, else ``cc``), the cache directory cannot be written, or ``DUALARM_COMPILE=0`` is set,
:func:`compiled` returns the Function as it is: the same results, slower.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import casadi as cs

#: The compiler's options, after the compiler itself: position-independent shared library, no FMA.
FLAGS = ("-O2", "-ffp-contract=off", "-fPIC", "-shared")


def cache_dir() -> Path:
    """Where compiled Functions are kept.

    ``$DUALARM_CACHE_DIR``, else ``$XDG_CACHE_HOME/dualarm``, else ``~/.cache/dualarm``.
    """
    given = os.environ.get("DUALARM_CACHE_DIR")
    if given:
        return Path(given)
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "dualarm"


def _compiler() -> str | None:
    """The C compiler's path (``$CC``, else ``cc``), or None when there is none or ``DUALARM_COMPILE=0``."""
    if os.environ.get("DUALARM_COMPILE", "1") == "0":
        return None
    return shutil.which(os.environ.get("CC") or "cc")


def compiled(function: cs.Function) -> cs.Function:
    """``function`` as a compiled shared library loaded by ``casadi.external``.

    Built on the first call with these sources anywhere on the machine; or ``function`` itself when
    it cannot be compiled (see the module docstring).
    """
    compiler = _compiler()
    if compiler is None:
        return function
    generator = cs.CodeGenerator(f"{function.name()}.c")
    generator.add(function)
    source = generator.dump()
    command = (compiler, *FLAGS)
    key = hashlib.sha256("\0".join((*command, source)).encode()).hexdigest()[:20]
    library = cache_dir() / f"{function.name()}-{key}.so"
    try:
        if not library.is_file():
            _build(source, command, library)
        return cs.external(function.name(), str(library))
    except (OSError, subprocess.SubprocessError, RuntimeError):
        return function


def _build(source: str, command: tuple[str, ...], library: Path) -> None:
    """Compile ``source`` into ``library``, written under a temporary name and renamed.

    So that processes building the same library at once never load a half-written one.
    """
    library.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=library.parent, prefix=".build-") as tmp:
        c_file, built = Path(tmp) / "function.c", Path(tmp) / library.name
        c_file.write_text(source)
        subprocess.run([*command, str(c_file), "-o", str(built), "-lm"], check=True, capture_output=True, timeout=300)
        os.replace(built, library)
