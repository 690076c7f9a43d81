"""Offscreen rendering with two passes per frame instead of three.

``mujoco.Renderer`` renders once for RGB, once for depth and once for segmentation. Depth and
segmentation both want the flat, untextured segmentation mode, and one ``mjr_readPixels`` call
reads the colour (object ids) and depth buffers of the same pass, so a frame here costs one
textured pass and one segmentation pass. Depth is converted from the reversed-Z buffer to metric
planar depth exactly as ``mujoco.Renderer`` does.
"""

from __future__ import annotations

import mujoco
import numpy as np

__all__ = ["OffscreenRenderer"]


def _gl_context_class():
    """The GL context class MUJOCO_GL asks for (default EGL), read when a renderer is made, so
    importing mujoco before polar_sim does not lock in a windowed backend."""
    import os

    backend = os.environ.get("MUJOCO_GL", "egl").lower()
    if backend == "osmesa":
        from mujoco.osmesa import GLContext
    elif backend == "glfw":
        from mujoco.glfw import GLContext
    else:
        from mujoco.egl import GLContext
    return GLContext


class OffscreenRenderer:
    """One GL context and framebuffer of a fixed size for a model.

    ``render(data, camera, option)`` returns ``(rgb (H,W,3) uint8 | None, depth (H,W) float32 |
    None, geom_ids (H,W) int32 | None)``; depth is metres along the optical axis with ``inf``
    where no geom was hit; geom ids are -1 there.
    """

    def __init__(self, model, height, width, max_geom=20000):
        if width > model.vis.global_.offwidth or height > model.vis.global_.offheight:
            raise ValueError(
                f"width/height: {width}x{height} exceeds the scene's offscreen buffer "
                f"{model.vis.global_.offwidth}x{model.vis.global_.offheight}")
        self.model = model
        self.height, self.width = height, width
        self._gl = _gl_context_class()(width, height)
        self._gl.make_current()
        self._ctx = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_100)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._ctx)
        self._ctx.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        self.scene = mujoco.MjvScene(model, maxgeom=max_geom)
        self._rect = mujoco.MjrRect(0, 0, width, height)
        self._pert = mujoco.MjvPerturb()
        self._rgb = np.empty((height, width, 3), np.uint8)
        self._ids = np.empty((height, width, 3), np.uint8)
        self._zbuf = np.empty((height, width), np.float32)
        extent = model.stat.extent
        znear = np.float32(model.vis.map.znear * extent)
        zfar = np.float32(model.vis.map.zfar * extent)
        c = -(zfar + znear) / (zfar - znear)
        d = -(np.float32(2) * zfar * znear) / (zfar - znear)
        self._c = np.float32(-0.5) * c - np.float32(0.5)
        self._d = np.float32(-0.5) * d

    def update(self, data, camera, option):
        """Build the scene from ``data`` seen by ``camera`` (id, name or ``MjvCamera``)."""
        if isinstance(camera, mujoco.MjvCamera):
            cam = camera
        else:
            cam = mujoco.MjvCamera()
            cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
            cam.fixedcamid = camera if isinstance(camera, (int, np.integer)) else self.model.camera(camera).id
        self._gl.make_current()
        mujoco.mjv_updateScene(self.model, data, option, self._pert, cam, mujoco.mjtCatBit.mjCAT_ALL, self.scene)

    def render(self, data, camera, option, *, rgb=True, depth=True, ids=True):
        self.update(data, camera, option)
        out_rgb = out_depth = out_ids = None
        if rgb:
            mujoco.mjr_render(self._rect, self.scene, self._ctx)
            mujoco.mjr_readPixels(self._rgb, None, self._rect, self._ctx)
            out_rgb = np.flipud(self._rgb).copy()
        if depth or ids:
            flags = self.scene.flags
            old = flags.copy()
            flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = True
            flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = True
            try:
                mujoco.mjr_render(self._rect, self.scene, self._ctx)
                mujoco.mjr_readPixels(self._ids, self._zbuf if depth else None, self._rect, self._ctx)
            finally:
                np.copyto(flags, old)
            seg = self._ids.astype(np.int32)
            seg = np.flipud(seg[..., 0] | (seg[..., 1] << 8) | (seg[..., 2] << 16))
            # Segment colour k + 1 belongs to scene geom k; 0 is background.
            n = self.scene.ngeom
            lut = np.full(n + 1, -1, np.int32)
            geoms = self.scene.geoms
            for k in range(n):
                g = geoms[k]
                if g.segid >= 0 and g.objtype == mujoco.mjtObj.mjOBJ_GEOM:
                    lut[g.segid + 1] = g.objid
            out_ids = lut[np.minimum(seg, n)]
            if depth:
                z = np.flipud(self._zbuf).astype(np.float64)
                metric = (self._d / (z + self._c)).astype(np.float32)
                metric[out_ids < 0] = np.inf
                out_depth = metric
        return out_rgb, out_depth, out_ids

    def close(self):
        if self._gl is not None:
            self._gl.make_current()
            self._ctx.free()
            self._gl.free()
            self._gl = None

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass
