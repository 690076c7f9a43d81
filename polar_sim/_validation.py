"""Input checks shared by every package (after scikit-learn's ``utils/validation.py``).

This module is the shared validation layer and public by design: every package (``gpis``,
``ground``, ``tracking``, ``baselines``, ``metrics``, ``sim``, ``envs``) imports the names in
``__all__`` from it. Each function takes caller input and returns a clean value, or raises
``ValueError`` (a wrong value or shape) or ``TypeError`` (a wrong kind of object) whose message
starts with the argument's name and says what was expected and what was received. Modules call
these instead of ``np.asarray``.

What counts as numeric: integer and floating dtypes, and Python/NumPy ints and floats. Refused
with ``TypeError``: ``None``, strings (also numeric strings such as ``"0.1"``), bytes, booleans
(``True`` is not a length), complex values, and object arrays (they hold ``None`` or mixed
types). Nothing is coerced silently.
"""

from __future__ import annotations

import numbers

import numpy as np

from polar_sim.errors import NotUpdatedError

__all__ = [
    "as_float_array",
    "as_points",
    "as_pose",
    "as_pose2d",
    "as_image",
    "as_depth",
    "as_ranges",
    "as_angles",
    "as_intrinsics",
    "as_positive_float",
    "as_float",
    "as_int",
    "as_bool",
    "as_rng",
    "as_image_size",
    "check_choice",
    "check_options",
    "check_same_length",
    "check_updated",
]


def as_float_array(x, name):
    """Return ``x`` as a float64 ndarray (no copy when it already is one), any shape.

    Raises ``TypeError`` for None, strings and bytes, booleans, complex values, object arrays
    and anything else that is not an array of real numbers (see the module docstring), and
    ``ValueError`` for a ragged sequence.
    """
    if x is None:
        raise TypeError(f"{name}: expected an array of numbers, got None")
    if isinstance(x, (str, bytes)):
        raise TypeError(f"{name}: expected an array of numbers, got {type(x).__name__} {_short(x)}")
    if isinstance(x, np.ndarray):
        a = x
    else:
        try:
            a = np.asarray(x)
        except ValueError as exc:  # ragged: "inhomogeneous shape"
            raise ValueError(f"{name}: expected a rectangular array of numbers, got a ragged "
                             f"{type(x).__name__}") from exc
        except Exception as exc:  # noqa: BLE001 - arbitrary objects can fail in any way
            raise TypeError(f"{name}: expected an array of numbers, got {type(x).__name__}") from exc
    kind = a.dtype.kind
    if kind not in "iuf":
        what = {"b": "booleans", "c": "complex numbers", "O": "objects (None or mixed types)",
                "U": "strings", "S": "bytes", "M": "datetimes", "m": "timedeltas"}.get(kind, f"dtype {a.dtype}")
        raise TypeError(f"{name}: expected real numbers (an integer or float array), got {what}")
    return np.asarray(a, dtype=np.float64)


def _short(x, n=40):
    r = repr(x)
    return r if len(r) <= n else r[: n - 3] + "..."


# Kept for callers that imported the old private name; new code uses as_float_array.


def as_points(x, dim, name, *, allow_empty=False):
    """Return ``x`` as a finite float64 array of shape (n, dim)."""
    a = as_float_array(x, name)
    if a.ndim != 2 or a.shape[1] != dim:
        raise ValueError(f"{name}: expected shape (n, {dim}), got {a.shape}")
    if a.shape[0] == 0 and not allow_empty:
        raise ValueError(f"{name}: expected at least one point, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name}: contains NaN or inf")
    return a


def as_pose(T, name):
    """Return ``T`` as a float64 4x4 rigid transform, checking that it is a proper SE(3) element.

    The rotation block must be orthonormal with determinant +1 to within 1e-6 and the last row
    must be (0, 0, 0, 1).
    """
    a = as_float_array(T, name)
    if a.shape != (4, 4):
        raise ValueError(f"{name}: expected a 4x4 homogeneous transform, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name}: contains NaN or inf")
    R = a[:3, :3]
    if not np.allclose(a[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise ValueError(f"{name}: last row must be (0, 0, 0, 1), got {a[3].tolist()}")
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ValueError(f"{name}: rotation block is not a proper rotation (R^T R != I or det < 0)")
    return a.copy()


def as_pose2d(p, name):
    """Return a planar pose ``(x, y, theta)`` as a finite float64 array of shape (3,)."""
    a = as_float_array(p, name)
    if a.shape != (3,):
        raise ValueError(f"{name}: expected (x, y, theta) of shape (3,), got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name}: contains NaN or inf")
    return a.copy()


def as_image(img, name, *, channels=3, dtype=np.uint8, shape=None):
    """Check an image: ndarray of ``dtype`` with shape (H, W, channels) (or (H, W) if channels is None).

    Returns the array itself (no copy): images are large and the modules only read them.
    """
    if not isinstance(img, np.ndarray):
        raise TypeError(f"{name}: expected a numpy array, got {type(img).__name__}")
    want = (2,) if channels is None else (3,)
    if img.ndim != want[0] or (channels is not None and img.shape[2] != channels):
        exp = "(H, W)" if channels is None else f"(H, W, {channels})"
        raise ValueError(f"{name}: expected shape {exp}, got {img.shape}")
    if img.shape[0] < 1 or img.shape[1] < 1:
        raise ValueError(f"{name}: image is empty, shape {img.shape}")
    if dtype is not None and img.dtype != dtype:
        raise ValueError(f"{name}: expected dtype {np.dtype(dtype).name}, got {img.dtype}")
    if shape is not None and tuple(img.shape[:2]) != tuple(shape):
        raise ValueError(f"{name}: expected image size {tuple(shape)}, got {tuple(img.shape[:2])}")
    return img


def as_depth(depth, name, *, shape=None):
    """Return a metric depth image (H, W) as float64; NaN/inf/0 mean "no return"; negatives raise."""
    if not isinstance(depth, np.ndarray):
        raise TypeError(f"{name}: expected a numpy array, got {type(depth).__name__}")
    if depth.ndim != 2:
        raise ValueError(f"{name}: expected shape (H, W), got {depth.shape}")
    if depth.shape[0] < 1 or depth.shape[1] < 1:
        raise ValueError(f"{name}: depth image is empty, shape {depth.shape}")
    if shape is not None and tuple(depth.shape) != tuple(shape):
        raise ValueError(f"{name}: expected shape {tuple(shape)}, got {depth.shape}")
    d = as_float_array(depth, name)
    with np.errstate(invalid="ignore"):
        if (d < 0).any():
            raise ValueError(f"{name}: contains negative depths (use 0, NaN or inf for no return)")
    return d


def as_ranges(r, name, *, n=None):
    """Return ranges (n,) as float64. NaN and inf mean "no return" and are kept; negatives raise."""
    a = as_float_array(r, name)
    if a.ndim != 1:
        raise ValueError(f"{name}: expected shape (n,), got {a.shape}")
    if n is not None and a.shape[0] != n:
        raise ValueError(f"{name}: expected {n} values to match the angles, got {a.shape[0]}")
    with np.errstate(invalid="ignore"):
        if (a < 0).any():
            raise ValueError(f"{name}: contains negative ranges (use inf or NaN for no return)")
    return a


def as_angles(a, name):
    """Return beam angles (n,) in radians as a finite float64 array."""
    x = as_float_array(a, name)
    if x.ndim != 1:
        raise ValueError(f"{name}: expected shape (n,), got {x.shape}")
    if not np.isfinite(x).all():
        raise ValueError(f"{name}: contains NaN or inf")
    return x


def as_intrinsics(K, name="K"):
    """Return a 3x3 pinhole intrinsics matrix with positive focal lengths as float64."""
    a = as_float_array(K, name)
    if a.shape != (3, 3):
        raise ValueError(f"{name}: expected a 3x3 intrinsics matrix, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name}: contains NaN or inf")
    if not (a[0, 0] > 0 and a[1, 1] > 0):
        raise ValueError(f"{name}: focal lengths must be positive, got fx={a[0, 0]}, fy={a[1, 1]}")
    if not np.allclose(a[2], [0.0, 0.0, 1.0]):
        raise ValueError(f"{name}: last row must be (0, 0, 1), got {a[2].tolist()}")
    return a.copy()


def _check_real_scalar(x, name):
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, numbers.Real):
        raise TypeError(f"{name}: expected a real number, got {type(x).__name__} {_short(x)}")
    return float(x)


def as_positive_float(x, name, *, allow_zero=False):
    """Return ``x`` as a finite float > 0 (or >= 0 when ``allow_zero``)."""
    v = _check_real_scalar(x, name)
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        cmp = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name}: expected a finite number {cmp}, got {x!r}")
    return v


def as_float(x, name, *, minimum=None, maximum=None, exclusive_minimum=False, allow_inf=False):
    """Return ``x`` as a float within ``[minimum, maximum]`` (``(minimum, maximum]`` when
    ``exclusive_minimum``). NaN always raises; ``inf`` raises unless ``allow_inf``."""
    v = _check_real_scalar(x, name)
    if np.isnan(v) or (np.isinf(v) and not allow_inf):
        raise ValueError(f"{name}: expected a finite number, got {x!r}")
    lo_bad = minimum is not None and (v <= minimum if exclusive_minimum else v < minimum)
    if lo_bad or (maximum is not None and v > maximum):
        lo = "-inf" if minimum is None else repr(float(minimum))
        hi = "inf" if maximum is None else repr(float(maximum))
        raise ValueError(f"{name}: expected a number in {'(' if exclusive_minimum else '['}{lo}, {hi}], got {x!r}")
    return v


def as_int(x, name, *, minimum=None, maximum=None):
    """Return ``x`` as an int, optionally within ``[minimum, maximum]``. Floats (also 3.0),
    strings and booleans raise ``TypeError``."""
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, numbers.Integral):
        raise TypeError(f"{name}: expected an integer, got {type(x).__name__} {_short(x)}")
    v = int(x)
    if minimum is not None and v < minimum:
        raise ValueError(f"{name}: expected an integer >= {minimum}, got {v}")
    if maximum is not None and v > maximum:
        raise ValueError(f"{name}: expected an integer <= {maximum}, got {v}")
    return v


def as_bool(x, name):
    """Return ``x`` as a bool: only ``True``/``False`` (or NumPy booleans); ``"no"``, ``0`` and
    ``None`` raise ``TypeError`` instead of being taken by their truth value."""
    if not isinstance(x, (bool, np.bool_)):
        raise TypeError(f"{name}: expected True or False, got {type(x).__name__} {_short(x)}")
    return bool(x)


def as_rng(seed, name="seed"):
    """Return a ``numpy.random.Generator`` from None, an int seed or a Generator."""
    if isinstance(seed, np.random.Generator):
        return seed
    if seed is None:
        return np.random.default_rng()
    if isinstance(seed, numbers.Integral) and not isinstance(seed, (bool, np.bool_)):
        if seed < 0:
            raise ValueError(f"{name}: expected a seed >= 0, got {seed}")
        return np.random.default_rng(int(seed))
    raise TypeError(f"{name}: expected None, an int or a numpy.random.Generator, got {type(seed).__name__}")


def as_image_size(x, name, *, maximum=8192):
    """Return an image size ``(width, height)`` in pixels as a tuple of two ints in
    ``1..maximum``. Anything else (one number, three numbers, 0, floats, strings, booleans) raises
    ``TypeError``/``ValueError`` naming ``name`` and the limit."""
    if isinstance(x, (str, bytes)) or not hasattr(x, "__len__") or len(x) != 2:
        raise TypeError(f"{name}: expected (width, height) in pixels, got {_short(x)}")
    return tuple(as_int(v, name, minimum=1, maximum=maximum) for v in x)


def check_options(options, allowed, name="options"):
    """Return ``reset(options=...)`` as a dict: None or a dict whose keys are among ``allowed``
    (a tuple of names; empty when the environment takes none). Unknown keys raise ``ValueError``
    naming them and listing the allowed ones; anything but a dict raises ``TypeError``."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise TypeError(f"{name}: expected None or a dict, got {type(options).__name__} {_short(options)}")
    unknown = sorted(map(repr, set(options) - set(allowed)))
    if unknown:
        takes = f"it takes {sorted(allowed)}" if allowed else "this environment takes none"
        raise ValueError(f"{name}: unknown option(s) {', '.join(unknown)}; {takes}")
    return dict(options)


def _number_kind(x):
    """'bool', 'int' or 'float' for Python and numpy scalars, None for anything else."""
    if isinstance(x, (bool, np.bool_)):
        return "bool"
    if isinstance(x, (int, np.integer)):
        return "int"
    if isinstance(x, (float, np.floating)):
        return "float"
    return None


def check_choice(value, choices, name):
    """Raise ``ValueError`` listing the valid choices if ``value`` is not one of them."""
    try:
        ok = bool(value in choices)
    except (TypeError, ValueError):  # unhashable, or an array whose truth value is ambiguous
        ok = False
    # 2.0 == 2 and True == 1: an integer choice takes an integer, not a float or a bool
    if ok and _number_kind(value) is not None:
        ok = any(_number_kind(c) == _number_kind(value) and c == value for c in choices)
    if not ok:
        valid = ", ".join(repr(c) for c in choices)
        raise ValueError(f"{name}: unknown value {value!r}; expected one of {valid}")
    return value


def check_same_length(**arrays):
    """Raise ``ValueError`` if the named arrays do not share their first dimension."""
    lengths = {}
    for k, v in arrays.items():
        try:
            lengths[k] = len(v)
        except TypeError:
            raise TypeError(f"{k}: expected a sequence or array, got {type(v).__name__}") from None
    if len(set(lengths.values())) > 1:
        desc = ", ".join(f"{k} has {n}" for k, n in lengths.items())
        raise ValueError(f"expected equal lengths: {desc}")


def check_updated(obj, attr):
    """Raise ``NotUpdatedError`` if ``obj`` has no fitted attribute ``attr`` yet."""
    if not hasattr(obj, attr):
        raise NotUpdatedError(
            f"{type(obj).__name__} has no data yet: call update()/process() before querying"
        )
