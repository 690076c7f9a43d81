"""Exception types shared by every polar_sim package."""

__all__ = ["PolarSimError", "NotUpdatedError"]


class PolarSimError(ValueError):
    """Base class for errors that polar_sim raises on bad input or bad state.

    It subclasses ``ValueError`` so that callers catching ``ValueError`` also catch it; the CLI
    turns it into exit code 1 with a one-line message.
    """


class NotUpdatedError(PolarSimError):
    """A query was made on an estimator that has not received any data yet."""
