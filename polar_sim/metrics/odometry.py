"""odometry metrics."""

__all__ = []
