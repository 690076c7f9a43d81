"""pose metrics."""

__all__ = []
