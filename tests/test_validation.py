"""The shared validators (polar_sim._validation) under generated input (hypothesis, derandomized):
every value is either returned clean or refused with ValueError/TypeError naming the argument;
booleans, complex numbers, strings, object arrays and None are always refused (issue 17, finding 6)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from polar_sim import _validation as V

SETTINGS = settings(derandomize=True, max_examples=150, deadline=None)

any_dtype = st.one_of(hnp.integer_dtypes(), hnp.unsigned_integer_dtypes(), hnp.floating_dtypes(),
                      hnp.boolean_dtypes(), hnp.complex_number_dtypes(), hnp.unicode_string_dtypes(max_len=4))
arrays = hnp.arrays(any_dtype, hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=5))


def _refused_kind(a):
    return np.asarray(a).dtype.kind not in "iuf"


def _call(fn, x):
    try:
        return fn(x), None
    except (ValueError, TypeError) as exc:
        return None, exc


@pytest.mark.parametrize("fn, name", [
    (lambda x: V.as_points(x, 2, "pts"), "pts"), (lambda x: V.as_pose(x, "T"), "T"),
    (lambda x: V.as_pose2d(x, "pose2d"), "pose2d"), (lambda x: V.as_ranges(x, "ranges"), "ranges"),
    (lambda x: V.as_angles(x, "angles"), "angles"), (lambda x: V.as_intrinsics(x, "K"), "K"),
    (lambda x: V.as_float_array(x, "x"), "x"),
])
@SETTINGS
@given(a=arrays)
def test_array_validators(fn, name, a):
    out, exc = _call(fn, a)
    if exc is not None:
        assert str(exc).startswith(name + ":"), str(exc)
        return
    assert not _refused_kind(a), f"{a.dtype} accepted"
    assert out.dtype == np.float64


# None, strings (also numeric ones), bytes, booleans and complex values never pass as numbers.
@SETTINGS
@given(x=st.one_of(st.none(), st.text(max_size=5), st.binary(max_size=5), st.booleans(), st.complex_numbers(),
                   st.lists(st.booleans(), min_size=1, max_size=4), st.lists(st.text(max_size=3), min_size=1, max_size=4)))
def test_non_numbers_refused(x):
    for fn in (lambda v: V.as_float_array(v, "arg"), lambda v: V.as_float(v, "arg"), lambda v: V.as_int(v, "arg"),
               lambda v: V.as_positive_float(v, "arg")):
        out, exc = _call(fn, x)
        assert exc is not None and str(exc).startswith("arg:"), (x, out)


# Scalars: a finite number within the bounds comes back as a float; anything else is refused by name.
@SETTINGS
@given(x=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(min_value=-10**40, max_value=10**40)))
def test_as_float_bounds(x):
    out, exc = _call(lambda v: V.as_float(v, "v", minimum=0.0, maximum=10.0), x)
    if exc is None:
        assert 0.0 <= out <= 10.0 and np.isfinite(out)
    else:
        assert str(exc).startswith("v:") and not (np.isfinite(float(x)) and 0 <= float(x) <= 10)


# Object arrays (None inside) and bools are refused; ints and lists of numbers are accepted.
def test_finding_6_cases():
    for bad in (np.array([1.0, None], object), np.array([1.0, 2.0], object), [True, False], [1 + 0j, 2], ["1", "2"], "0.1"):
        with pytest.raises(TypeError, match="^r:"):
            V.as_ranges(bad, "r")
    np.testing.assert_array_equal(V.as_ranges([1, 2], "r"), [1.0, 2.0])
    with pytest.raises(TypeError, match="kinematic"):
        V.as_bool("no", "kinematic")
    with pytest.raises(ValueError, match="seed"):
        V.as_rng(-1)
    with pytest.raises(ValueError, match="mode"):
        V.check_choice(True, (1, 2), "mode")
    with pytest.raises(ValueError, match="mode"):
        V.check_choice([1], {"a", "b"}, "mode")
    # an array (ambiguous truth value) and a float for an integer choice name the argument too
    for bad in (np.array([2, 2]), 2.0, np.float32(1.0)):
        with pytest.raises(ValueError, match="^downsample: unknown value"):
            V.check_choice(bad, (1, 2), "downsample")
    assert V.check_choice(np.int64(2), (1, 2), "downsample") == 2
    assert V.check_choice(np.float64(0.5), (0.5, 1.0), "scale") == 0.5
