"""The kernels compiled ahead of time (``polar_sim.gpis._native``): how a process finds them and
falls back to numba's JIT. (A module is built, and compared with the JIT, in
``test_native_build.py``; its cold start is timed in ``benchmarks/bench_gpis_coldstart.py``.)"""

import numba as nb
import numpy as np
import pytest

from polar_sim.gpis import _native


# without a compiled module, K answers with the JIT dispatcher itself
def test_kernels_fall_back_to_the_jit(monkeypatch, tmp_path):
    monkeypatch.setenv("POLAR_SIM_NATIVE_DIR", str(tmp_path))       # an empty folder
    k = _native._Kernels()
    assert k.faithful is _native._REGISTRY["faithful"]
    assert not k.compiled
    with pytest.raises(AttributeError):
        k.not_a_kernel


# a compiled function that rejects the argument types hands the call to the JIT dispatcher
def test_compiled_call_falls_back_on_other_types():
    def compiled(x):
        if not isinstance(x, np.ndarray) or x.dtype != np.float64:
            raise TypeError("can't unbox")
        return float(x.sum())

    jit = nb.njit(lambda x: float(x.sum()))
    c = _native._Compiled(compiled, jit)
    assert c(np.ones(3)) == 3.0
    assert c(np.ones(3, np.int32)) == 3.0


# a compiled signature reads any array as C-contiguous without checking (a reversed view came back
# as other points' answers, off by up to 1.97): a call with a strided array goes to the JIT
# dispatcher, which compiles for its layout
def test_compiled_call_falls_back_on_strided_arrays():
    def compiled(x, out):               # what a compiled kernel does: the buffer, read contiguously
        flat = np.frombuffer(x.data if x.flags.c_contiguous else x.base.data, np.float64)
        out[:] = flat[: len(out)]

    @nb.njit
    def jit(x, out):
        for i in range(len(out)):
            out[i] = x[i]

    c = _native._Compiled(compiled, jit)
    x = np.arange(6.0)
    for arg, want in ((x, x), (x[::-1], x[::-1]), (x[::2], x[::2])):
        out = np.zeros(len(want))
        c(arg, out)
        np.testing.assert_array_equal(out, want)
    out = np.zeros(3)
    c(x[::2], out)
    compiled(x[::2], out)               # the test can fail: the compiled call itself is wrong there
    assert not np.array_equal(out, x[::2])


# the key names the sources, numba, Python and the CPU: a module from other sources is not loaded
def test_source_key_follows_the_sources(monkeypatch, tmp_path):
    key = _native.source_key()
    assert len(key) == 20 and key == _native.source_key()
    (tmp_path / f"{_native.module_name('0' * 20)}.cpython-311-x86_64-linux-gnu.so").write_bytes(b"")
    monkeypatch.setenv("POLAR_SIM_NATIVE_DIR", str(tmp_path))
    assert _native._load() is None                                  # another key's file is ignored


# a broken module file is reported and ignored, never fatal
def test_broken_module_is_ignored(monkeypatch, tmp_path, caplog):
    name = _native.module_name(_native.source_key())
    (tmp_path / f"{name}.cpython-311-x86_64-linux-gnu.so").write_bytes(b"not a shared library")
    monkeypatch.setenv("POLAR_SIM_NATIVE_DIR", str(tmp_path))
    assert _native._load() is None
    assert "not loaded" in caplog.text


# every kernel name is registered once
def test_entry_refuses_a_second_kernel_of_the_same_name():
    with pytest.raises(ValueError, match="faithful"):
        _native.entry(nb.njit(faithful))


def faithful():
    return 0
