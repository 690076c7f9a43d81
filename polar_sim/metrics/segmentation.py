"""segmentation metrics."""

__all__ = []
