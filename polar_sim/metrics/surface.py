"""surface metrics."""

__all__ = []
