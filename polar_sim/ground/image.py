"""Image preparation: 2x pyramid reduction, grey, and the 216-label quantised HSV index (spec §2.1, §5.1)."""

from __future__ import annotations

import cv2
import numba
import numpy as np

__all__ = ["reduce2x", "grey", "hsv216", "N_LABELS"]

#: Number of colour labels: 6 hue x 6 saturation x 6 value levels (spec §5.1).
N_LABELS = 216


def reduce2x(rgb):
    """One 2x Gaussian pyramid reduction (5-tap [1,4,6,4,1]/16, keep even rows and columns).

    (H, W, 3) -> (⌈H/2⌉, ⌈W/2⌉, 3).

    Pixel ``i`` of the output is centred on pixel ``2i`` of the input, so intrinsics halve exactly
    in 0-based pixel-centre coordinates.
    """
    return cv2.pyrDown(rgb)


def grey(rgb):
    """Rounded 0.299 R + 0.587 G + 0.114 B of an (H,W,3) uint8 RGB image, (H,W) uint8."""
    return cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)


@numba.njit(cache=True, nogil=True)
def _hsv216_kernel(rgb, code, out):  # pragma: no cover - compiled
    h, w = out.shape
    c6_255 = np.float32(6.0 / 255.0)
    s_max = np.float32(0.999)
    two6 = np.float32(2.0 / 6.0)
    four6 = np.float32(4.0 / 6.0)
    wrap = np.float32(5.0 / 6.0) if code else np.float32(1.0)
    six = np.float32(6.0)
    for i in range(h):
        for j in range(w):
            r = np.int32(rgb[i, j, 0])
            g = np.int32(rgb[i, j, 1])
            b = np.int32(rgb[i, j, 2])
            mx = max(r, max(g, b))
            mn = min(r, min(g, b))
            d = mx - mn
            qv = np.int32(np.float32(mx) * c6_255)
            if qv > 5:
                qv = 5
            if mx == 0:
                s = np.float32(0.0)
            else:
                s = np.float32(d) / np.float32(mx)
            if s > s_max:
                s = s_max
            qs = np.int32(six * s)
            if d == 0:
                # [code] computes NaN here, which the x86 cast turns into bin 0; [fix] defines it as 0.
                qh = 0
            else:
                den = np.float32(6 * d)
                if r >= g and r >= b:
                    hh = np.float32(g - b) / den
                elif g >= b:
                    hh = two6 + np.float32(b - r) / den
                else:
                    hh = four6 + np.float32(r - g) / den
                if hh < 0:
                    hh = hh + wrap  # B7: the published code adds 5/6 instead of 1
                qh = np.int32(six * hh)
                if qh > 5:
                    qh = 5
            out[i, j] = qh + 6 * qs + 36 * qv


def hsv216(rgb, compat="fixed"):
    """216-label HSV index image of an (H,W,3) uint8 RGB image, (H,W) uint8 in 0..215.

    Label = q_h + 6 q_s + 36 q_v with six levels per channel, exactly as spec §5.1.
    ``compat="code"`` reproduces the published hue wrap (B7: negative hues get +5/6, bin 5 unreachable).
    """
    rgb = np.ascontiguousarray(rgb)
    out = np.empty(rgb.shape[:2], dtype=np.uint8)
    _hsv216_kernel(rgb, compat == "code", out)
    return out
