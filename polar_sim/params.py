"""One module contract, after scikit-learn's estimators.

Every online module (``GPISMap2D``/``3D``, ``GroundVO``, ``ObjectTracker``) follows it:

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
  field changed (validated by the config itself).
"""

from __future__ import annotations

import copy
import dataclasses
import inspect

__all__ = ["Parameterised", "split_nested", "replace_fields", "check_fields"]


class Parameterised:
    """Mixin giving a class the module contract above; see the module docstring."""

    #: Parameter values of the published behaviour (the named preset ``published()``).
    PUBLISHED: dict = {}

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
