"""One module contract, after scikit-learn's estimators.

Every online module (``GPISMap2D``/``3D``, ``GroundVO``, ``ObjectTracker``) and every baseline
(``polar_sim.baselines``) follows it:

- the constructor only stores its documented parameters, under their own names;
- :meth:`~Parameterised.get_params` / :meth:`~Parameterised.set_params` read and change them
  (``set_params`` checks the new values first and leaves the object unchanged if they are bad);
- learned state lives in attributes ending in ``_``, created on the first ``update``/``process``;
  :meth:`~Parameterised.reset` deletes it;
- parameters are validated in one place, the class's ``_check_params()``, which returns the clean
  values (and raises ``ValueError``/``TypeError`` naming the parameter);
- the published behaviour is a named preset, ``Cls.published(**overrides)``: the parameters in the
  class's ``PUBLISHED`` mapping, not flags threaded through the code;
- a parameter may be a frozen dataclass of one stage's settings (a *stage config*): as in
  scikit-learn's nested estimators, ``get_params(deep=True)`` also lists its fields as
  ``stage__field``, and ``set_params(stage__field=value)`` replaces the config by a copy with that
  field changed (validated by the config itself);
- the class declares what the contract checks (:func:`polar_sim.testing.check_module`) need to
  know of it in :data:`~Parameterised.TAGS`, a :class:`Tags` (after scikit-learn's estimator
  tags): its per-frame method, its query, its random-state parameter, whether it saves, and where
  a small valid data set (:class:`CheckData`) comes from. The module does not import the checks.
"""

from __future__ import annotations

import copy
import dataclasses
import importlib
import inspect
from typing import ClassVar

__all__ = ["Parameterised", "Tags", "CheckData", "split_nested", "replace_fields", "check_fields"]


@dataclasses.dataclass(frozen=True)
class CheckData:
    """A small valid data set for the contract checks of one module class.

    Attributes
    ----------
    init : dict
        Constructor arguments an instance needs to fit these frames (intrinsics, a model, ...);
        the rest keep their defaults.
    frames : tuple of tuple
        The positional arguments of each call of the per-frame method (:attr:`Tags.update`), in order.
    query : tuple
        Positional arguments of one call of the query (:attr:`Tags.query`).
    prepare : tuple of (str, tuple)
        ``(method, args)`` calls that must come before the first frame (a filter's ``initialize``).
    """

    init: dict = dataclasses.field(default_factory=dict)
    frames: tuple = ()
    query: tuple = ()
    prepare: tuple = ()


@dataclasses.dataclass(frozen=True)
class Tags:
    """What the contract checks need to know of a module class (after scikit-learn's estimator tags).

    Attributes
    ----------
    update : str or None
        The per-frame (or fit) method; None for a class without learned state.
    query : str or None
        A method that reads the learned state without changing it.
    requires_update : bool
        The query raises :class:`polar_sim.errors.NotUpdatedError` before the first ``update``
        (False for an exact, stateless model).
    random_state : str or None
        The constructor parameter that seeds every random choice.
    saves : bool
        ``save(path)`` and the class method ``load(path)`` round-trip the learned state.
    data : str or None
        ``"package.module:function"`` returning the class's :class:`CheckData`; imported only
        when a check runs, so that a module does not import its synthetic data (or the checks).
    """

    update: str | None = None
    query: str | None = None
    requires_update: bool = True
    random_state: str | None = None
    saves: bool = False
    data: str | None = None

    def check_data(self) -> CheckData:
        """The :class:`CheckData` named by :attr:`data`."""
        if self.data is None:
            raise ValueError("data: this class declares no check data")
        module, _, name = self.data.partition(":")
        return getattr(importlib.import_module(module), name)()


class Parameterised:
    """Mixin giving a class the module contract above; see the module docstring."""

    #: Parameter values of the published behaviour (the named preset ``published()``).
    PUBLISHED: dict = {}
    #: What the contract checks need to know of the class (see :class:`Tags`).
    TAGS: ClassVar[Tags] = Tags()

    def __polar_tags__(self) -> Tags:
        """The class's :class:`Tags` (a subclass may derive them from its parameters, as
        scikit-learn's ``__sklearn_tags__`` does)."""
        return self.TAGS

    @classmethod
    def _param_names(cls):
        sig = inspect.signature(cls.__init__)
        return [p.name for p in sig.parameters.values()
                if p.name != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]

    def get_params(self, deep=True) -> dict:
        """The constructor parameters, by name; with ``deep``, also every field of a stage config
        parameter as ``stage__field``."""
        out = {}
        for k in self._param_names():
            v = out[k] = getattr(self, k)
            if deep and _is_config(v):
                out.update({f"{k}__{f.name}": getattr(v, f.name) for f in dataclasses.fields(v)})
        return out

    def set_params(self, **params):
        """Change parameters (``name=value``, or ``stage__field=value`` inside a stage config); unknown
        names or bad values raise and leave the object unchanged.

        Learned state is kept; call :meth:`reset` to start over with the new parameters.
        """
        names = self._param_names()
        flat, nested = split_nested(params)
        unknown = sorted(set(flat) - set(names)) + sorted(f"{s}__{f}" for s, fs in nested.items()
                                                          if s not in names for f in fs)
        if unknown:
            raise ValueError(f"{unknown[0]}: unknown parameter of {type(self).__name__}; valid: {', '.join(names)}")
        trial = copy.copy(self)
        for k, v in flat.items():
            setattr(trial, k, v)
        for stage, fields in nested.items():
            setattr(trial, stage, replace_fields(getattr(trial, stage), stage, fields))
        if hasattr(trial, "_check_params"):
            trial._check_params()
        for k in set(flat) | set(nested):
            setattr(self, k, getattr(trial, k))
        return self

    def reset(self):
        """Forget everything learned (the ``_``-suffixed attributes); parameters stay."""
        for k in [k for k in vars(self) if k.endswith("_") and not k.startswith("__")]:
            delattr(self, k)
        return self

    @classmethod
    def published(cls, *args, **overrides):
        """An instance with the published behaviour's parameters (``PUBLISHED``), and overrides."""
        if not cls.PUBLISHED:
            raise ValueError(f"{cls.__name__} has no published preset")
        names = cls._param_names()
        unknown = sorted(set(overrides) - set(names))
        if unknown:
            raise ValueError(f"{unknown[0]}: unknown parameter of {cls.__name__}; valid: {', '.join(names)}")
        return cls(*args, **{**cls.PUBLISHED, **overrides})

    def __repr__(self):
        sig = inspect.signature(type(self).__init__)
        parts = []
        for k in self._param_names():
            default = sig.parameters[k].default
            v = getattr(self, k, None)
            try:
                same = default is not inspect.Parameter.empty and bool(v == default)
            except (ValueError, TypeError):     # arrays compare element-wise
                same = False
            if not same and (default is not inspect.Parameter.empty):
                parts.append(f"{k}={v!r}")
        return f"{type(self).__name__}({', '.join(parts)})"


def _is_config(v):
    return dataclasses.is_dataclass(v) and not isinstance(v, type)


def split_nested(params):
    """({name: value}, {stage: {field: value}}) of keyword parameters with ``stage__field`` names."""
    flat, nested = {}, {}
    for k, v in params.items():
        stage, sep, field = k.partition("__")
        if sep:
            nested.setdefault(stage, {})[field] = v
        else:
            flat[k] = v
    return flat, nested


def replace_fields(config, stage, fields):
    """A copy of the stage config ``config`` with ``fields`` changed, validated by the config; errors
    name the parameter as ``stage__field``."""
    if not _is_config(config):
        raise ValueError(f"{stage}__{next(iter(fields))}: {stage} is not a stage config "
                         f"(got {type(config).__name__})")
    check_fields(type(config), stage, fields)
    try:
        return dataclasses.replace(config, **fields)
    except (TypeError, ValueError) as exc:
        raise type(exc)(f"{stage}__{exc}") from None


def check_fields(config_type, stage, fields):
    """Raise ``ValueError`` naming ``stage__field`` for a name in ``fields`` that ``config_type`` lacks."""
    known = {f.name for f in dataclasses.fields(config_type)}
    unknown = sorted(set(fields) - known)
    if unknown:
        raise ValueError(f"{stage}__{unknown[0]}: unknown field of {config_type.__name__}; valid: "
                         f"{', '.join(sorted(known))}")
