"""Dense, direct alignment of the ground between two images through the plane-induced homography.

The ground is the plane y = h of the level frame (camera height h, y down). A camera moving along a
unicycle arc of length s with a yaw change a between two images maps a ground pixel of the first
image to the second by H(s, a) = M R_yᵀ (I − p(s, a) nᵀ / h) M⁻¹, with p the second camera's
position in the first's level frame, n = (0, 1, 0) and M the level-frame-to-pixel map (the same
homography as :func:`polar_sim.ground.frontend.ground_homography`). :func:`align_ground` finds
(s, a) by Gauss–Newton on the photometric error of ground pixels of the first image against the
second one (forward additive, analytic Jacobian, Tukey weights), coarse to fine, from a predicted
(s, a). Every textured pixel of the ground counts, not only corners, so the metric distance s holds
where a corner detector finds almost nothing on the ground (a faint grain on one colour).

The fit returns its covariance (from the Gauss–Newton Hessian and the residuals) and an aliasing
flag: on a texture that repeats along the path (tiles, painted stripes) shifts of s by a period fit
too. The flag is raised when the cost along s has another minimum, within ``alias_range`` of the
solution, whose cost is within ``alias_margin`` of the best; the caller then down-weights the fit.

:func:`ground_evidence` turns a converged fit into per-pixel self-labels: ground where the pixel
agrees with the second image under the ground homography clearly better than under the rotation-only
homography of points at infinity (parallax that only the ground explains).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numba
import numpy as np

__all__ = ["DenseFit", "Pyramid", "WARP_MODELS", "align_ground", "ground_evidence", "label_points", "fuse_measurements",
           "select_pixels"]

_TUKEY_C = 4.685  # Tukey biweight constant (95 % efficiency at the normal law)
_N = np.array([0.0, 1.0, 0.0])  # ground normal in the level frame (y down)
_BIG = float(np.finfo(np.float64).max)  # what np.nan_to_num makes of inf


@dataclass(frozen=True)
class DenseFit:
    """Result of :func:`align_ground`.

    Attributes
    ----------
    ok : bool
        A fit converged on enough pixels (``n_pixels`` >= the minimum, finite, non-singular).
    s, a : float
        Arc length along the path (m) and yaw change (rad, about +y) between the two images.
    cov : ndarray of shape (2, 2)
        Covariance of (s, a), from the Gauss–Newton Hessian scaled by the robust residual variance.
    n_pixels : int
        Ground pixels with a non-zero weight at the solution.
    sigma : float
        Robust scale of the photometric residuals at the solution, grey levels.
    aliased : bool
        The cost along s has another minimum as good as the solution's (a periodic texture).
    iterations : int
        Gauss–Newton iterations run (all levels).
    params : tuple
        All fitted parameters: (s, a), then the pitch and roll changes, or the pitch change and the
        ground's shape coefficients, of the models that have them.
    band_spread : float
        Half the difference of s fitted on the nearer and on the farther half of the pixels, m: where
        the ground is not the plane the model assumes (a slope or a crest ahead), the two disagree.
    model : str
        The warp model fitted (a key of :data:`WARP_MODELS`).
    slip : float
        The sideways slip per radian of yaw change it was fitted with, 1/rad.
    """

    ok: bool
    s: float
    a: float
    cov: np.ndarray
    n_pixels: int
    sigma: float
    aliased: bool
    iterations: int
    params: tuple = ()
    band_spread: float = np.nan
    model: str = "plane"
    slip: float = 0.0


def _failed(s0, a0, iterations=0):
    return DenseFit(False, float(s0), float(a0), np.full((2, 2), np.inf), 0, np.nan, False, iterations)


def _gradients(img):
    gx = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    gy = cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
    return gx, gy


class Pyramid:
    """A grey image (H, W) uint8 prepared for :func:`align_ground`: per level (0 = full size, then
    halved with ``cv2.INTER_AREA``) the image Gaussian-smoothed by ``sigma`` px of that level's full-size
    scale (2^level sigma), as float32, and its gradients. Made once per image, used by the two image
    pairs it belongs to."""

    def __init__(self, grey, levels, sigma):
        self.shape = grey.shape
        self.img, self.grad = [], []
        src = grey.astype(np.float32)
        for lv in range(levels):
            f = 2 ** lv
            img = cv2.GaussianBlur(src, (0, 0), sigma * f) if sigma > 0 else src
            if f > 1:
                img = cv2.resize(img, (grey.shape[1] // f, grey.shape[0] // f), interpolation=cv2.INTER_AREA)
            self.img.append(img)
            self.grad.append(_gradients(img))
        # (H, W, 3): the image and its gradients, sampled together by one remap per Gauss–Newton iteration
        self.stack = [cv2.merge([i, *g]) for i, g in zip(self.img, self.grad)]

    @property
    def levels(self):
        return len(self.img)


def select_pixels(grad, mask, *, block, max_pixels, min_gradient):
    """Template pixels (m, 2) (column, row) inside ``mask`` (H, W) bool of an image with gradients
    ``grad`` ((H, W), (H, W)): in every ``block`` x ``block`` cell the pixel of largest gradient, if above
    ``min_gradient`` (grey levels per px); at most ``max_pixels``, evenly spread over them. Spreading
    the pixels over the ground keeps a few strong edges (an obstacle's foot) from dominating a faint
    ground."""
    rows_any = np.flatnonzero(mask.any(axis=1))
    if len(rows_any) == 0:
        return np.zeros((0, 2))
    r0 = rows_any[0] - rows_any[0] % block  # only the rows of the mask, on the block grid
    r1 = rows_any[-1] + 1
    xy = _block_maxima(mask[r0:r1], grad[0][r0:r1], grad[1][r0:r1], block, np.float32(min_gradient * min_gradient))
    xy[:, 1] += r0
    if len(xy) > max_pixels:
        # An even subset, not the strongest: on a faint ground the strongest are all off the ground.
        xy = xy[np.linspace(0, len(xy) - 1, max_pixels).astype(np.intp)]
    return xy


@numba.njit(cache=True, nogil=True)
def _block_maxima(mask, gx, gy, block, min_sq):  # pragma: no cover - compiled
    """(column, row) (m, 2) float of the largest squared gradient (float32) of each ``block`` x ``block``
    cell of the masked images (H, W), the first in row order if tied, where it is above ``min_sq``;
    cells in row order."""
    hb, wb = mask.shape[0] // block, mask.shape[1] // block
    out = np.empty((hb * wb, 2))
    n = 0
    for bi in range(hb):
        for bj in range(wb):
            best, arg = np.float32(-1.0), 0
            for k in range(block * block):
                y, x = bi * block + k // block, bj * block + k % block
                val = gx[y, x] * gx[y, x] + gy[y, x] * gy[y, x] if mask[y, x] else np.float32(0.0)
                if val > best:
                    best, arg = val, k
            if best > min_sq:
                out[n, 0], out[n, 1] = bj * block + arg % block, bi * block + arg // block
                n += 1
    return out[:n]


def _rot_x(b):
    cb, sb = np.cos(b), np.sin(b)
    return np.array([[1.0, 0.0, 0.0], [0.0, cb, -sb], [0.0, sb, cb]])


def _rot_z(c):
    cc, sc = np.cos(c), np.sin(c)
    return np.array([[cc, -sc, 0.0], [sc, cc, 0.0], [0.0, 0.0, 1.0]])


#: Parameters of each warp model: the unicycle step (s, a) over a level plane, plus the pitch change b
#: of the chassis between the images (hills), plus its roll change c (side slopes); or (s, a, b) over a
#: ground through the point h below the camera that slopes across the image (``"side_slope"``: the
#: chassis leans in a turn, or the road is cambered) or is curved (``"surface"``: slope, curvature and
#: side slope).
WARP_MODELS = {"plane": 2, "pitch": 3, "pitch_roll": 4, "side_slope": 4, "surface": 6}
#: Prior standard deviations of the surface model's shape (forward slope, forward curvature 1/m, side
#: slope) around the level plane.
SURFACE_PRIOR_SD = (0.05, 0.002, 0.03)
#: The shape coefficients (c1, c2, c3) each ground-shape model fits; the others stay 0.
_SHAPES = {"side_slope": (2,), "surface": (0, 1, 2)}


def _step(s, a, f1, f2, slip):
    """The camera's displacement (3,) in the level frame of the first image over a unicycle step of arc
    length s and yaw change a (f1, f2 = (1 - cos a)/a, sin a/a): along the chord, turned sideways by
    arctan(-slip a) (the camera's sideways slip, ``MotionConfig.slip`` over the step's duration)."""
    if not slip:
        return s * np.array([f1, 0.0, f2])
    b = np.arctan(-slip * a)
    cb, sb = np.cos(b), np.sin(b)
    return s * np.array([f1 * cb + f2 * sb, 0.0, f2 * cb - f1 * sb])


class _Warp:
    """The ground homography of one pyramid level as a function of the motion parameters p, and its
    derivatives: p = (s, a) arc length (m) and yaw change (rad) of a unicycle step over the plane y = h
    of the level frame; ``model="pitch"`` adds the pitch change b (rad, about the level x axis) between
    the images, ``"pitch_roll"`` also the roll change c (about z): a chassis that pitches and rolls
    over uneven ground, the ground still the plane h below the camera."""

    def __init__(self, cam, h, model="plane", slip=0.0):
        self.M = cam.K @ cam.R_lc.T  # level-frame normalised coordinates -> pixels
        self.Minv = np.linalg.inv(self.M)
        self.h = h
        self.n_params = WARP_MODELS[model]
        self.slip = float(slip)

    def level(self, p):
        """The homography (3, 3) in level-frame normalised coordinates."""
        s, a = p[0], p[1]
        ca, sa = np.cos(a), np.sin(a)
        if abs(a) < 1e-4:  # (1 - cos a)/a and sin a/a by their series
            f1, f2 = a / 2 - a ** 3 / 24, 1 - a * a / 6
        else:
            f1, f2 = (1 - ca) / a, sa / a
        R = np.array([[ca, 0.0, -sa], [0.0, 1.0, 0.0], [sa, 0.0, ca]])  # R_y(a)ᵀ
        if len(p) > 2:
            R = _rot_x(p[2]).T @ R
        if len(p) > 3:
            R = _rot_z(p[3]).T @ R
        return R @ (np.eye(3) - np.outer(_step(s, a, f1, f2, self.slip), _N) / self.h)

    def matrices(self, p):
        """The pixel homography H(p) (3, 3) and its derivatives (n_params, 3, 3) (central differences)."""
        p = np.asarray(p, dtype=np.float64)
        H = self.M @ self.level(p) @ self.Minv
        dH = np.empty((len(p), 3, 3))
        for i, e in enumerate((1e-6, 1e-7, 1e-7, 1e-7)[:len(p)]):  # steps in m, then rad
            d = np.zeros(len(p))
            d[i] = e
            dH[i] = self.M @ ((self.level(p + d) - self.level(p - d)) / (2 * e)) @ self.Minv
        return H, dH

    def points(self, xh, p, jacobian=False):
        """Positions (m, 2) in the second image of pixels ``xh`` (m, 3) (homogeneous) of the first under
        p; with ``jacobian`` also their derivatives (n_params, m, 2)."""
        H, dH = self.matrices(p) if jacobian else (self.M @ self.level(np.asarray(p, float)) @ self.Minv, None)
        X = xh @ H.T
        with np.errstate(divide="ignore", invalid="ignore"):
            x = X[:, :2] / X[:, 2:3]
            if not jacobian:
                return x
            J = np.empty((len(dH), len(xh), 2))
            for i in range(len(dH)):
                dX = xh @ dH[i].T
                J[i] = (dX[:, :2] - x * dX[:, 2:3]) / X[:, 2:3]
        return x, J


class _SurfaceWarp:
    """The warp of ground pixels over a ground y = h + c1 z + c2 z² + c3 x (level frame of the first
    image, through the point h below the camera) under the step (s, a) and pitch change b:
    p = (s, a, b) then the fitted shape coefficients (``shape``: indices into (c1, c2, c3); the others
    are 0). A pixel's depth is the ray's first intersection with the surface; the shape carries a
    Gaussian prior (``prior_sd``, indexed as (c1, c2, c3)) around the level plane, as the 6-parameter
    RANSAC model carries a ridge."""

    _STEPS = (1e-5, 1e-6, 1e-6, 1e-6, 1e-7, 1e-6)  # forward-difference steps of s, a, b, c1, c2, c3

    def __init__(self, cam, h, shape=(0, 1, 2), prior_sd=SURFACE_PRIOR_SD, slip=0.0):
        self.M = cam.K @ cam.R_lc.T
        self.Minv = np.linalg.inv(self.M)
        self.h = h
        self.slip = float(slip)
        self.shape = tuple(shape)
        self.n_params = 3 + len(self.shape)
        self.prior_sd = np.r_[np.inf, np.inf, np.inf, [prior_sd[i] for i in self.shape]]
        self._shape = np.array(self.shape, np.int64)
        self._steps = np.array(self._STEPS[:3] + tuple(self._STEPS[3 + i] for i in self.shape))

    def points(self, xh, p, jacobian=False):
        """As :meth:`_Warp.points` (forward differences for the Jacobian)."""
        x, J = _surface_points(xh, np.asarray(p, dtype=np.float64), self._shape, self.M, self.Minv, self.h,
                               self.slip, self._steps, jacobian)
        return (x, J) if jacobian else x


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _surface_points(xh, p, shape, M, Minv, h, slip, steps, jacobian):  # pragma: no cover - compiled
    """Pixel positions (m, 2) of the pixels ``xh`` (m, 3) (homogeneous) of :class:`_SurfaceWarp` under p
    (k,) (NaN where a ray misses the ground ahead) and, with ``jacobian``, their forward differences
    (k, m, 2) over ``steps`` (k,). One compiled pass: the warp is evaluated 1 + k times per Gauss–Newton
    iteration, and as numpy array operations each pass cost ~0.1 ms in call overhead on 1,500 pixels."""
    k, m = p.shape[0], xh.shape[0]
    rays = np.empty((m, 2))  # (x, y) of the rays at z = 1
    for i in range(m):
        r0 = Minv[0, 0] * xh[i, 0] + Minv[0, 1] * xh[i, 1] + Minv[0, 2] * xh[i, 2]
        r1 = Minv[1, 0] * xh[i, 0] + Minv[1, 1] * xh[i, 1] + Minv[1, 2] * xh[i, 2]
        r2 = Minv[2, 0] * xh[i, 0] + Minv[2, 1] * xh[i, 1] + Minv[2, 2] * xh[i, 2]
        rays[i, 0], rays[i, 1] = r0 / r2, r1 / r2
    n = k + 1 if jacobian else 1
    out = np.empty((n, m, 2))
    A = np.empty((3, 3))
    Z = np.empty(m)
    for j in range(n):
        q = p.copy()
        if j > 0:
            q[j - 1] += steps[j - 1]
        s, a, b = q[0], q[1], q[2]
        c = np.zeros(3)
        for i in range(shape.shape[0]):
            c[shape[i]] = q[3 + i]
        ca, sa = np.cos(a), np.sin(a)
        if abs(a) < 1e-4:  # (1 - cos a)/a and sin a/a by their series
            f1, f2 = a / 2 - a ** 3 / 24, 1 - a * a / 6
        else:
            f1, f2 = (1 - ca) / a, sa / a
        dx, dz = s * f1, s * f2  # the step (see _step), turned sideways by arctan(-slip a)
        if slip != 0.0:
            t = np.arctan(-slip * a)
            ct, st = np.cos(t), np.sin(t)
            dx, dz = s * (f1 * ct + f2 * st), s * (f2 * ct - f1 * st)
        cb, sb = np.cos(b), np.sin(b)
        # A = M R with R = R_x(b)ᵀ R_y(a)ᵀ = [[ca, 0, -sa], [sb sa, cb, sb ca], [cb sa, -sb, cb ca]]
        for r in range(3):
            A[r, 0] = M[r, 0] * ca + M[r, 1] * (sb * sa) + M[r, 2] * (cb * sa)
            A[r, 1] = M[r, 1] * cb - M[r, 2] * sb
            A[r, 2] = -M[r, 0] * sa + M[r, 1] * (sb * ca) + M[r, 2] * (cb * ca)
        if j == 0 or j > 3:  # the ray's depth: the step and the rotation (s, a, b) do not move it
            for i in range(m):
                B = rays[i, 1] - c[0] - c[2] * rays[i, 0]
                Z[i] = 2.0 * h / (B + np.sqrt(B * B - 4.0 * c[1] * h))  # the near root, stable for c2 -> 0
        for i in range(m):
            u, v, z = rays[i, 0], rays[i, 1], Z[i]
            if not (np.isfinite(z) and z > 0):
                out[j, i, 0] = np.nan
                out[j, i, 1] = np.nan
                continue
            X0, X1, X2 = u * z - dx, v * z, z - dz
            P0 = A[0, 0] * X0 + A[0, 1] * X1 + A[0, 2] * X2
            P1 = A[1, 0] * X0 + A[1, 1] * X1 + A[1, 2] * X2
            P2 = A[2, 0] * X0 + A[2, 1] * X1 + A[2, 2] * X2
            out[j, i, 0] = P0 / P2
            out[j, i, 1] = P1 / P2
    J = np.empty((n - 1, m, 2))
    for j in range(n - 1):
        for i in range(m):  # loops, not an array expression: numba compiles those 4 s slower
            J[j, i, 0] = (out[j + 1, i, 0] - out[0, i, 0]) / steps[j]
            J[j, i, 1] = (out[j + 1, i, 1] - out[0, i, 1]) / steps[j]
    return out[0], J


def _make_warp(model, cam, h, slip=0.0):
    return _SurfaceWarp(cam, h, _SHAPES[model], slip=slip) if model in _SHAPES else _Warp(cam, h, model, slip)


def _sample(img, xy):
    """Bilinear samples (m,) of ``img`` (H, W), or (m, c) of ``img`` (H, W, c), at ``xy`` (m, 2) float
    (NaN outside the image)."""
    if len(xy) == 0:
        return np.zeros((0,) + img.shape[2:])
    mx = np.ascontiguousarray(xy[:, 0], dtype=np.float32).reshape(1, -1)
    my = np.ascontiguousarray(xy[:, 1], dtype=np.float32).reshape(1, -1)
    out = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=(np.nan,) * 4)
    return out[0].astype(np.float64)


def _tukey(r, scale):
    u = r / (_TUKEY_C * scale)
    return np.where(np.abs(u) < 1.0, (1.0 - u * u) ** 2, 0.0)


def _costs(warp, tmpl, img, xh, prior_w, ps, scale):
    """Mean Tukey cost (n,) of the template pixels under each parameter vector of ``ps`` (n, k) (pixels
    leaving the image count as outliers), sampled by one remap."""
    x = np.concatenate([warp.points(xh, p) for p in ps])
    v = _sample(img, x).reshape(len(ps), len(xh)) - tmpl
    u = np.where(np.isfinite(v), v / (_TUKEY_C * scale), np.inf)
    rho = np.where(np.abs(u) < 1.0, 1.0 - (1.0 - u * u) ** 3, 1.0)
    return np.sum(prior_w * rho, axis=1) / np.sum(prior_w)


def _gauss_newton(warp, tmpl, img, stack, xh, prior_w, p, *, max_iter, floor, min_pixels, tol, scale=True):
    """Gauss–Newton on the motion parameters p at one level; returns (p, H (k, k), sigma, n, iterations)
    or None. ``stack`` (H, W, 3) is the image ``img`` and its x and y gradients. Stops when a step moves
    the template's pixels by less than ``tol`` px (median). Without ``scale`` the returned sigma is the
    robust scale of the first iteration, not the residuals' spread at the solution."""
    p = np.array(p, dtype=np.float64)
    H = np.zeros((len(p), len(p)))
    # MAP: the photometric cost in units of its variance, plus the shape prior (none: infinite variance)
    prior_var = np.asarray(getattr(warp, "prior_sd", np.full(len(p), np.inf)), dtype=np.float64) ** 2
    sigma, n, it = np.nan, 0, 0  # the first iteration sets the residual scale, kept for the level
    for it in range(1, max_iter + 1):
        x0, Jp = warp.points(xh, p, jacobian=True)
        rgg = _sample(stack, x0)
        ok, H, step, sigma, n, moved = _gn_iteration(rgg[:, 0] - tmpl, rgg[:, 1], rgg[:, 2], Jp, prior_w, sigma,
                                                     floor, min_pixels, prior_var, p)
        if not ok:
            return None
        p = p + step
        if moved < tol:
            break
    if scale:
        # The noise scale at the solution (for the covariance and the self-labels): the weighted RMS of the
        # final residuals under the Tukey weights of a robust scale, i.e. the spread of the inliers.
        r = _sample(img, warp.points(xh, p)) - tmpl
        ok = np.isfinite(r)
        r, w0 = r[ok], prior_w[ok]
        if len(r):
            w = w0 * _tukey(r, max(1.4826 * float(np.median(np.abs(r))), floor))
            sigma = max(float(np.sqrt(np.sum(w * r * r) / max(np.sum(w), 1e-300))), floor)
    return p, H, sigma, n, it


def _gn_iteration(r, gx, gy, Jp, prior_w, sigma, floor, min_pixels, prior_var, p):
    """One Gauss–Newton step from the residuals r (m,), the image gradients (m,) at the warped pixels
    (NaN outside the image) and the warp's Jacobian Jp (k, m, 2) at p (k,): (ok, H (k, k), step (k,),
    sigma, n, moved), with H the normal matrix (prior included), n the pixels of non-zero weight and
    ``moved`` the median motion (px) of the pixels under the step. A NaN ``sigma`` is set from these
    residuals (robust, floored at ``floor``). Not ok with fewer than ``min_pixels`` pixels inside or
    weighted, or a singular H."""
    k = len(p)
    ok, H, g, sigma, n = _normal_equations(r, gx, gy, Jp, prior_w, sigma, floor, min_pixels)
    if not ok:
        return False, H, np.zeros(k), sigma, n, 0.0
    P = sigma * sigma / prior_var
    H[np.diag_indices(k)] += P
    g += P * p
    if not np.all(np.isfinite(H)) or np.linalg.cond(H) > 1e12:
        return False, H, np.zeros(k), sigma, n, 0.0
    step = -np.linalg.solve(H, g)
    return True, H, step, sigma, n, _median_motion(step, Jp, r, gx, gy)


@numba.njit(cache=True, nogil=True)
def _inside(r, gx, gy):  # pragma: no cover - compiled
    """The pixels (m,) bool whose residual and gradients are finite (inside the image)."""
    ok = np.empty(r.shape[0], np.bool_)
    for i in range(r.shape[0]):
        ok[i] = np.isfinite(r[i]) and np.isfinite(gx[i]) and np.isfinite(gy[i])
    return ok


@numba.njit(cache=True, nogil=True)
def _normal_equations(r, gx, gy, Jp, prior_w, sigma, floor, min_pixels):  # pragma: no cover - compiled
    """(ok, Σ w J Jᵀ (k, k), Σ w J r (k,), sigma, n) over the pixels inside (:func:`_inside`): J the
    photometric Jacobian (gx, gy)·Jp (NaN entries of Jp as 0, as ``np.nan_to_num``), w the prior
    weight times Tukey's biweight of r at scale sigma, n the count of non-zero weights. A NaN sigma is
    set from the residuals (1.4826 x their median absolute value, floored at ``floor``). Not ok with
    fewer than ``min_pixels`` pixels inside or weighted."""
    k, m = Jp.shape[0], r.shape[0]
    H, g, J = np.zeros((k, k)), np.zeros(k), np.empty(k)
    ok = _inside(r, gx, gy)
    n_in = np.count_nonzero(ok)
    if n_in < min_pixels:
        return False, H, g, sigma, 0
    if np.isnan(sigma):
        a = np.empty(n_in)
        j = 0
        for i in range(m):
            if ok[i]:
                a[j] = abs(r[i])
                j += 1
        sigma = max(1.4826 * np.median(a), floor)
    c = _TUKEY_C * sigma
    big = _BIG
    n = 0
    for i in range(m):
        if not ok[i]:
            continue
        u = r[i] / c
        if abs(u) >= 1.0:
            continue
        w = prior_w[i] * (1.0 - u * u) ** 2
        if w == 0.0:
            continue
        n += 1
        for a in range(k):
            jx, jy = Jp[a, i, 0], Jp[a, i, 1]
            jx = 0.0 if np.isnan(jx) else min(max(jx, -big), big)
            jy = 0.0 if np.isnan(jy) else min(max(jy, -big), big)
            J[a] = gx[i] * jx + gy[i] * jy
        for a in range(k):
            wa = w * J[a]
            g[a] += wa * r[i]
            for b in range(a + 1):
                H[a, b] += wa * J[b]
    for a in range(k):
        for b in range(a):
            H[b, a] = H[a, b]
    return n >= min_pixels, H, g, sigma, n


@numba.njit(cache=True, nogil=True)
def _median_motion(step, Jp, r, gx, gy):  # pragma: no cover - compiled
    """Median over the pixels inside (:func:`_inside`) of |dx| + |dy|, the motion (px) of a pixel under
    the parameter step (k,) (NaN entries of Jp as 0)."""
    k = Jp.shape[0]
    ok = _inside(r, gx, gy)
    d = np.empty(np.count_nonzero(ok))
    j = 0
    for i in range(Jp.shape[1]):
        if not ok[i]:
            continue
        dx = dy = 0.0
        for a in range(k):
            jx, jy = Jp[a, i, 0], Jp[a, i, 1]
            dx += step[a] * (0.0 if np.isnan(jx) else jx)
            dy += step[a] * (0.0 if np.isnan(jy) else jy)
        d[j] = abs(dx) + abs(dy)
        j += 1
    return np.median(d)


def _aliased(warp, tmpl, img, xh, prior_w, p, scale, *, alias_range, alias_margin, steps=6, max_pixels=400):
    """Another minimum of the cost along s within ``alias_range`` m of the solution p as low (within
    ``alias_margin``, relative) as the solution's (on an evenly spread subset of the pixels)."""
    if len(xh) > max_pixels:
        sub = np.linspace(0, len(xh) - 1, max_pixels).astype(np.intp)
        tmpl, xh, prior_w = tmpl[sub], xh[sub], prior_w[sub]
    offs = np.linspace(-alias_range, alias_range, 2 * steps + 1)
    shifted = np.tile(p, (len(offs), 1))
    shifted[:, 0] += offs
    c = _costs(warp, tmpl, img, xh, prior_w, shifted, scale)
    best = c[steps]
    far = np.abs(offs) > 1.5 * alias_range / steps  # beyond the solution's own basin
    local = np.r_[False, (c[1:-1] <= c[:-2]) & (c[1:-1] <= c[2:]), False]
    return bool(np.any(local & far & (c <= best + alias_margin * (1.0 - best) + 1e-12)))


def _band_spread(warp, tmpl, cur, xh, w, p, floor, min_pixels, iterations=3):
    """Half the difference of s re-fitted (from p) on the pixels nearer and farther than the median
    image row (the depth bands of a level ground); NaN if a band fails."""
    near = xh[:, 1] >= np.median(xh[:, 1])
    s = []
    for band in (near, ~near):
        res = _gauss_newton(warp, tmpl[band], cur.img[0], cur.stack[0], xh[band], w[band], p, max_iter=iterations,
                            floor=floor, min_pixels=min_pixels, tol=0.0, scale=False)
        if res is None:
            return float("nan")
        s.append(res[0][0])
    return 0.5 * abs(s[0] - s[1])


def _level_pixels(prev, lv, mask, weights, *, block, max_pixels, min_gradient, gradient_weight):
    """Template pixels of level ``lv`` of ``prev``: homogeneous positions (m, 3), values (m,), weights (m,)."""
    f = 2 ** lv
    if f > 1:
        mask = cv2.resize(mask.astype(np.uint8), prev.img[lv].shape[::-1], interpolation=cv2.INTER_NEAREST) > 0
    xy = select_pixels(prev.grad[lv], mask, block=block, max_pixels=max_pixels, min_gradient=min_gradient)
    w = np.ones(len(xy))
    if weights is not None and len(xy):
        full = np.clip(np.rint(xy * f).astype(np.intp), 0, [weights.shape[1] - 1, weights.shape[0] - 1])
        w = weights[full[:, 1], full[:, 0]].astype(np.float64)
    if gradient_weight > 0 and len(xy):
        # Strong edges are the most sensitive to what the warp does not model (a texture's blur that
        # changes with distance, sub-pixel shading): weigh a pixel by c² / (c² + |∇I|²), as DSO does.
        g2 = _sample(prev.grad[lv][0], xy) ** 2 + _sample(prev.grad[lv][1], xy) ** 2
        w = w * gradient_weight ** 2 / (gradient_weight ** 2 + g2)
    return np.c_[xy, np.ones(len(xy))], _sample(prev.img[lv], xy), w


def align_ground(prev, cur, cam, h, s0, a0, *, mask, weights=None, block=2, max_pixels=1500, min_gradient=0.05,
                 min_pixels=200, max_iter=10, residual_floor=0.3, tol=0.05, gradient_weight=0.0, model="plane",
                 alias_range=0.0, alias_margin=0.2, slip=0.0):
    """Align the ground of ``prev`` to ``cur`` (two :class:`Pyramid`) through the ground homography.

    Parameters
    ----------
    cam : LevelCamera
        The full-size images' camera.
    h : float
        Camera height above the ground, m.
    s0, a0 : float
        Predicted arc length (m) and yaw change (rad) between the images.
    mask : ndarray of shape (H, W), bool
        Pixels of ``prev`` that may be ground (below the horizon, within the depth band).
    weights : ndarray of shape (H, W), optional
        Prior weight of each pixel of ``prev`` being ground (e.g. the learned P(ground)); 1 if None.
    block, max_pixels, min_gradient, min_pixels : see :func:`select_pixels`; a fit needs ``min_pixels``.
    max_iter, tol : int, float
        Gauss–Newton iterations per level, and the convergence test: a step that moves the pixels by
        less than ``tol`` px (median).
    residual_floor : float
        Lower bound of the robust residual scale, grey levels (8-bit quantisation).
    gradient_weight : float
        c of the gradient weight c² / (c² + |∇I|²) of each pixel, grey levels per px (0: none).
    model : {"plane", "pitch", "pitch_roll", "side_slope", "surface"}
        The parameters (:data:`WARP_MODELS`): also the chassis' pitch change, and its roll change; or a
        ground that slopes across the image; or a curved ground.
    alias_range, alias_margin : float
        Aliasing test along s (m; 0 = no test) and its relative cost margin (see the module docstring).
    slip : float
        The camera's sideways slip per radian of yaw change, 1/rad (``MotionConfig.slip`` / the time
        between the images): the step's direction is turned by arctan(-slip a) from its chord.

    Returns
    -------
    DenseFit
    """
    p, its = np.r_[s0, a0, np.zeros(WARP_MODELS[model] - 2)].astype(np.float64), 0
    for lv in range(prev.levels - 1, -1, -1):
        warp = _make_warp(model, cam.scaled(2.0 ** -lv) if lv else cam, h, slip)
        xh, tmpl, w = _level_pixels(prev, lv, mask, weights, block=block, max_pixels=max_pixels,
                                    min_gradient=min_gradient, gradient_weight=gradient_weight)
        if len(xh) < min_pixels:
            return _failed(s0, a0, its)
        res = _gauss_newton(warp, tmpl, cur.img[lv], cur.stack[lv], xh, w, p, max_iter=max_iter,
                            floor=residual_floor, min_pixels=min_pixels, tol=tol)
        if res is None:
            return _failed(s0, a0, its)
        p, Hm, scale, n, it = res
        its += it
    if not np.all(np.isfinite(p)):
        return _failed(s0, a0, its)
    cov = (scale ** 2 * np.linalg.inv(Hm))[:2, :2]
    spread = _band_spread(warp, tmpl, cur, xh, w, p, residual_floor, min_pixels // 2)
    aliased = alias_range > 0 and _aliased(warp, tmpl, cur.img[0], xh, w, p, scale, alias_range=alias_range,
                                           alias_margin=alias_margin)
    return DenseFit(True, float(p[0]), float(p[1]), cov, n, float(scale), aliased, its, tuple(float(x) for x in p),
                    spread, model, float(slip))


def _residual_maps(prev, cur, cam, h, fit, mask, window):
    """Windowed mean squared residuals (grey levels²) of ``prev``'s pixels against ``cur`` under the fitted
    ground motion (g) and under its rotation alone (i, where points at infinity go), over the rows of
    ``mask``: (g, i, r0, r1) with the maps of rows r0:r1, or None if the mask is empty."""
    p = np.array(fit.params or (fit.s, fit.a))
    warp = _make_warp(fit.model if fit.params else "plane", cam, h, fit.slip)
    rows = np.flatnonzero(mask.any(axis=1))
    if len(rows) == 0:
        return None
    r0, r1 = max(rows[0] - window, 0), min(rows[-1] + window + 1, prev.shape[0])
    yy, xx = np.mgrid[r0:r1, 0:prev.shape[1]]
    xh = np.stack([xx.ravel(), yy.ravel(), np.ones(xx.size)], axis=1).astype(np.float64)
    p_inf = p.copy()
    p_inf[0] = 0.0  # the same rotation, no translation
    p_img = prev.img[0][r0:r1]
    out = []
    for q in (p, p_inf):
        # The previous image's pixel x matches the current image at warp(x): sample the current image there.
        x = warp.points(xh, q).astype(np.float32)
        x[~np.isfinite(x)] = -1.0
        w = cv2.remap(cur.img[0], x[:, 0].reshape(xx.shape), x[:, 1].reshape(xx.shape), cv2.INTER_LINEAR,
                      borderMode=cv2.BORDER_REPLICATE)
        out.append(cv2.blur((w - p_img) ** 2, (window, window), borderType=cv2.BORDER_REPLICATE))
    return out[0], out[1], r0, r1


def ground_evidence(prev, cur, cam, h, fit, mask, *, window=7, agreement=2.0, support_threshold=None):
    """Per-pixel ground evidence (H, W) float32 of ``prev`` (a :class:`Pyramid`) under a converged fit:
    the windowed mean of (squared residual under the rotation alone, where points at infinity go) −
    (squared residual under the fitted ground motion), grey levels², where the fitted motion agrees
    with the pixel (windowed mean squared residual within ``agreement`` times the fit's residual scale)
    inside ``mask``; 0 elsewhere. Large where the pixel's parallax is the ground's; near 0 where the
    image has no texture to tell.

    With ``support_threshold`` (grey levels²) also returns the ground's support (H, W) bool: the pixels
    of ``mask`` connected (8-neighbours) to evidence above the threshold through pixels where the
    fitted motion agrees and the evidence says nothing either way (|evidence| <= threshold: no texture
    to tell), or where the evidence is above the threshold and the ground motion's residual is below a
    quarter of the one of points at infinity (a strong edge of the ground). Texture alone decides where evidence exists (the painted lines of a road, the grain of
    one patch); the support carries it over the untextured ground between them, up to where the motion
    stops agreeing (the textured edge of an obstacle) or the evidence says far (points at infinity)."""
    out = np.zeros(prev.shape, np.float32)
    maps = _residual_maps(prev, cur, cam, h, fit, mask, window)
    if maps is None:
        return out if support_threshold is None else (out, np.zeros(prev.shape, bool))
    g, i, r0, r1 = maps
    e = i - g
    # Near non-ground (a wall, a box) has parallax too: the ground motion must also fit the pixel.
    agree = mask[r0:r1] & (g <= (agreement * fit.sigma) ** 2)
    out[r0:r1] = np.where(agree, e, 0.0)
    if support_threshold is None:
        return out
    seeds = agree & (e > support_threshold)
    # Strong edges of the ground (paint on dark asphalt) leave residuals above the fit's scale, set by the
    # flat ground; they pass where the ground motion explains them 4x better than points at infinity do.
    edges = mask[r0:r1] & (e > support_threshold) & (g <= 0.25 * i)
    region = (seeds | edges | (agree & (np.abs(e) <= support_threshold))).astype(np.uint8)
    n, comp = cv2.connectedComponents(region, connectivity=8)
    keep = np.zeros(n, bool)
    keep[np.unique(comp[seeds])] = True
    keep[0] = False  # the background of connectedComponents
    support = np.zeros(prev.shape, bool)
    # The windowed residuals reach half a window past the ground's edge: keep the support inside it.
    support[r0:r1] = cv2.erode(keep[comp].view(np.uint8), np.ones((window, window), np.uint8)) > 0
    return out, support


def label_points(evidence, threshold, max_labels, step=4):
    """Up to ``max_labels`` pixel positions (m, 2) (column, row) on a ``step``-px grid where ``evidence``
    (H, W) exceeds ``threshold``, spread evenly over them (deterministic)."""
    grid = evidence[::step, ::step]
    rows, cols = np.nonzero(grid > threshold)
    if len(rows) > max_labels:
        pick = np.unique(np.linspace(0, len(rows) - 1, max_labels).astype(np.intp))
        rows, cols = rows[pick], cols[pick]
    return np.stack([cols * step, rows * step], axis=1).astype(np.float64)


def fuse_measurements(z1, var1, z2, var2, gate):
    """Inverse-variance fusion of two measurements of one quantity: returns (value, variance). Two that
    differ by more than ``gate`` standard deviations of their difference are not averaged: the one with
    the smaller variance is returned alone (one of them is an outlier, and the mean would be wrong too)."""
    v1, v2 = max(float(var1), 1e-300), max(float(var2), 1e-300)
    if not np.isfinite(v1) and not np.isfinite(v2):
        return (float(z1), v1) if v1 <= v2 else (float(z2), v2)
    if (z1 - z2) ** 2 > gate * gate * (v1 + v2):
        return (float(z1), v1) if v1 <= v2 else (float(z2), v2)
    w1, w2 = 1.0 / v1, 1.0 / v2
    return float((w1 * z1 + w2 * z2) / (w1 + w2)), float(1.0 / (w1 + w2))
