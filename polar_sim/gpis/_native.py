"""The GPIS kernels compiled ahead of time (``polar-sim compile``), with numba's JIT as fallback.

numba compiles a kernel on its first call in a process whose cache does not hold it: a cold
first ``GPISMap2D.update`` + ``query`` compiled some 60 kernels for 20-40 s. ``polar-sim compile``
(:func:`polar_sim.gpis.build_native.build`) compiles the kernels that Python calls, once, into an
extension module in a per-user folder; a process that finds a module built from the same
sources, for the same Python and the same CPU, calls it instead and compiles nothing on the
default path.

Kernel modules mark the kernels that Python calls with :func:`entry` (which returns the numba
dispatcher unchanged, so that kernels calling each other stay compiled together), and Python
code calls them through :data:`K` (``K.faithful(...)``): the compiled function where the module
has it, the JIT dispatcher otherwise (no module, a source changed, other argument types).
"""

from __future__ import annotations

import hashlib
import importlib.util
import logging
import os
import platform
import sys
from pathlib import Path

import numpy as np

logger = logging.getLogger(__name__)

__all__ = ["K", "entry", "native_dir", "source_key", "SOURCES"]

#: The modules whose kernels (and their callees) the compiled module holds: their text keys it.
SOURCES = ("_numeric", "_shells", "_tree", "_localgp", "_kernels", "_distance", "_query", "_obsgp", "_scan2d",
           "_fusion", "_icp")
_REGISTRY = {}


def entry(dispatcher):
    """Mark a numba kernel as called from Python (``K.<name>``); returns it unchanged."""
    name = dispatcher.py_func.__name__
    if name in _REGISTRY and _REGISTRY[name] is not dispatcher:
        raise ValueError(f"two GPIS kernels named {name!r}")
    _REGISTRY[name] = dispatcher
    return dispatcher


def native_dir():
    """Where ``polar-sim compile`` puts the module: ``$POLAR_SIM_NATIVE_DIR``, else
    ``~/.cache/polar_sim/native``."""
    d = os.environ.get("POLAR_SIM_NATIVE_DIR")
    return Path(d) if d else Path.home() / ".cache" / "polar_sim" / "native"


def _cpu():
    try:
        from llvmlite import binding

        return binding.get_host_cpu_name() + ";" + binding.get_host_cpu_features().flatten()
    except Exception:  # noqa: BLE001 (no llvmlite: no compiled module either)
        return "unknown"


def source_key():
    """Hash of the kernel sources, the numba version, the Python version and the CPU: a module
    is used only by a process with the same key."""
    import numba

    h = hashlib.sha256()
    here = Path(__file__).resolve().parent
    for name in SOURCES:
        h.update((here / f"{name}.py").read_bytes())
    reg = here.parent / "registration" / "gauss_newton.py"
    h.update(reg.read_bytes())
    h.update(f"{numba.__version__};{sys.version};{platform.machine()};{_cpu()}".encode())
    return h.hexdigest()[:20]


def module_name(key):
    return f"_gpis_native_{key}"


def _load():
    """The compiled module for this key, or None."""
    if os.environ.get("POLAR_SIM_NATIVE", "1") == "0":
        return None
    try:
        key = source_key()
        name = module_name(key)
        files = sorted(native_dir().glob(f"{name}*.so")) + sorted(native_dir().glob(f"{name}*.pyd"))
        if not files:
            logger.debug("no compiled GPIS kernels for key %s: numba compiles them on first use", key)
            return None
        spec = importlib.util.spec_from_file_location(name, files[0])
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        return mod
    except Exception as exc:  # noqa: BLE001 (a bad module must not stop the JIT)
        logger.warning("compiled GPIS kernels not loaded (%s); numba compiles them on first use", exc)
        return None


class _Compiled:
    """A compiled kernel; the JIT dispatcher answers calls whose argument types it lacks, and
    calls with an array that is not C-contiguous."""

    __slots__ = ("fn", "jit")

    def __init__(self, fn, jit):
        self.fn, self.jit = fn, jit

    def __call__(self, *args):
        # a compiled signature takes C-contiguous arrays and does not check the layout it is
        # given: a strided view would be read as if it were contiguous (wrong answers, no error);
        # the JIT dispatcher compiles for whatever layout comes
        for a in args:
            if isinstance(a, np.ndarray) and not a.flags.c_contiguous:
                return self.jit(*args)
        try:
            return self.fn(*args)
        except TypeError:
            return self.jit(*args)


class _Kernels:
    """``K.<name>``: the kernel marked with :func:`entry` under that name, compiled if it can."""

    def __init__(self):
        self._module = None
        self._loaded = False

    def __getattr__(self, name):
        if name.startswith("__") or name not in _REGISTRY:
            raise AttributeError(name)
        if not self._loaded:
            self._module = _load()
            self._loaded = True
        jit = _REGISTRY[name]
        fn = getattr(self._module, name, None) if self._module is not None else None
        out = jit if fn is None else _Compiled(fn, jit)
        setattr(self, name, out)
        return out

    @property
    def compiled(self):
        """Whether a compiled module was found (after the first kernel call)."""
        return self._module is not None


K = _Kernels()
