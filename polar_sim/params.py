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
  class's ``PUBLISHED`` mapping, not flags threaded through the code.
"""

from __future__ import annotations

import copy
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

    def get_params(self) -> dict:
        """The constructor parameters, by name."""
        return {k: getattr(self, k) for k in self._param_names()}

    def set_params(self, **params):
        """Change parameters; unknown names or bad values raise and leave the object unchanged.

        Learned state is kept; call :meth:`reset` to start over with the new parameters.
        """
        names = self._param_names()
        unknown = sorted(set(params) - set(names))
        if unknown:
            raise ValueError(f"{unknown[0]}: unknown parameter of {type(self).__name__}; valid: {', '.join(names)}")
        trial = copy.copy(self)
        for k, v in params.items():
            setattr(trial, k, v)
        if hasattr(trial, "_check_params"):
            trial._check_params()
        for k, v in params.items():
            setattr(self, k, v)
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
