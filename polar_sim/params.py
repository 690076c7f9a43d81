"""One module contract, after scikit-learn's estimators.

Every online module (``GPISMap2D``/``3D``, ``GroundVO``, ``ObjectTracker``) follows it:

- the constructor only stores its documented parameters, under their own names;
- :meth:`~Parameterised.get_params` / :meth:`~Parameterised.set_params` read and change them
  (``set_params`` checks the new values first and leaves the object unchanged if they are bad);
  a parameter that is a frozen dataclass (a *stage config*) has its fields reached as
  ``stage__field``, as scikit-learn's nested estimators do;
- learned state lives in attributes ending in ``_``, created on the first ``update``/``process``;
  :meth:`~Parameterised.reset` deletes it;
- parameters are validated in one place, the class's ``_check_params()``, which returns the clean
  values (and raises ``ValueError``/``TypeError`` naming the parameter);
- the published behaviour is a named preset, ``Cls.published(**overrides)``: the parameters in the
  class's ``PUBLISHED`` mapping, not flags threaded through the code.
"""

from __future__ import annotations

import copy
import dataclasses
import inspect

__all__ = ["Parameterised"]


class Parameterised:
    """Mixin giving a class the module contract above; see the module docstring."""

    #: Parameter values of the published behaviour (the named preset ``published()``).
    PUBLISHED: dict = {}

    @classmethod
    def _param_names(cls):
        sig = inspect.signature(cls.__init__)
        return [p.name for p in sig.parameters.values()
                if p.name != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]

    def get_params(self, deep: bool = True) -> dict:
        """The constructor parameters, by name; with ``deep``, also every field of a stage config
        (a dataclass-valued parameter) as ``stage__field``."""
        out = {k: getattr(self, k) for k in self._param_names()}
        if deep:
            for k, v in list(out.items()):
                if _is_stage(v):
                    out.update({f"{k}__{f.name}": getattr(v, f.name) for f in dataclasses.fields(v)})
        return out

    def set_params(self, **params):
        """Change parameters; unknown names or bad values raise and leave the object unchanged.

        ``stage__field=value`` changes one field of the stage config ``stage`` (a new config is made
        with :func:`dataclasses.replace`, which checks it). Learned state is kept; call
        :meth:`reset` to start over with the new parameters.
        """
        names = self._param_names()
        flat, nested = {}, {}
        for k, v in params.items():
            stage, sep, field = k.partition("__")
            if stage not in names:
                raise ValueError(f"{k}: unknown parameter of {type(self).__name__}; valid: {', '.join(names)}")
            if sep:
                nested.setdefault(stage, {})[field] = v
            else:
                flat[k] = v
        trial = copy.copy(self)
        for k, v in flat.items():
            setattr(trial, k, v)
        for stage, fields in nested.items():
            setattr(trial, stage, _replace(getattr(trial, stage), stage, fields))
        if hasattr(trial, "_check_params"):
            trial._check_params()
        for k in {*flat, *nested}:
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


def _is_stage(v):
    """A stage config: a dataclass instance (not a dataclass type)."""
    return dataclasses.is_dataclass(v) and not isinstance(v, type)


def _replace(config, stage, fields):
    """``config`` with ``fields`` changed (checked by its ``__post_init__``); errors name ``stage__field``."""
    if not _is_stage(config):
        raise ValueError(f"{stage}__{next(iter(fields))}: {stage} is not a stage config "
                         f"(got {type(config).__name__})")
    valid = [f.name for f in dataclasses.fields(config)]
    unknown = sorted(set(fields) - set(valid))
    if unknown:
        raise ValueError(f"{stage}__{unknown[0]}: unknown field of {type(config).__name__}; valid: "
                         f"{', '.join(valid)}")
    try:
        return dataclasses.replace(config, **fields)
    except (TypeError, ValueError) as exc:
        raise type(exc)(f"{stage}__{exc}") from None
