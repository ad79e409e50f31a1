"""Offscreen rendering with pyrender through EGL: the only module that touches OpenGL.

One ``OffscreenRenderer`` per image size per process, cached in a module-level
dict and never deleted: deleting one tears EGL down for the whole process.
Never fork a process that holds a renderer (use the spawn start method).
"""

from __future__ import annotations

import atexit
import math
import os

import numpy as np

from scenes.world import MAX_TEXTURE_PX, World, box_mesh, vehicle_boxes

__all__ = ["RendererUnavailableError", "get_renderer", "gl_info", "SceneRenderer", "GL_SYSTEM_PACKAGES"]

GL_SYSTEM_PACKAGES = "libegl1 libegl-mesa0 libgl1-mesa-dri"

# (width, height) -> pyrender.OffscreenRenderer; lives as long as the process
_RENDERERS: dict[tuple[int, int], object] = {}
_GL_INFO: dict[str, str] = {}

# OpenCV camera axes (x right, y down, z forward) -> OpenGL camera axes (x right, y up, z back)
_CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])


class RendererUnavailableError(RuntimeError):
    """No OpenGL (EGL) renderer could be created in this process."""


def _pyrender():
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    try:
        import pyrender
    except Exception as err:  # ImportError, or OpenGL failing to find libEGL at import
        raise RendererUnavailableError(
            f"cannot import pyrender with PYOPENGL_PLATFORM={os.environ['PYOPENGL_PLATFORM']}: {err}. "
            f"Install the system packages: apt-get install {GL_SYSTEM_PACKAGES}") from err
    return pyrender


def get_renderer(width_px: int, height_px: int):
    """The process's renderer for this image size (created once, reused, never deleted)."""
    key = (int(width_px), int(height_px))
    r = _RENDERERS.get(key)
    if r is None:
        pyrender = _pyrender()
        try:
            r = pyrender.OffscreenRenderer(key[0], key[1])
        except Exception as err:
            raise RendererUnavailableError(
                f"cannot create an offscreen OpenGL renderer ({type(err).__name__}: {err}). "
                f"Headless rendering needs EGL with Mesa: apt-get install {GL_SYSTEM_PACKAGES}; "
                "and PYOPENGL_PLATFORM=egl") from err
        _RENDERERS[key] = r
        if not _GL_INFO:
            _GL_INFO.update(_query_gl_strings())
    return r


@atexit.register
def _release_at_exit() -> None:
    # Only at interpreter exit: left to garbage collection during shutdown, pyrender's
    # destructors run after PyOpenGL's modules are gone and print import errors.
    while _RENDERERS:
        _, r = _RENDERERS.popitem()
        try:
            r.delete()
        except Exception:
            pass


def _query_gl_strings() -> dict[str, str]:
    try:
        from OpenGL import GL
        return {k: (GL.glGetString(e) or b"").decode(errors="replace")
                for k, e in (("gl_vendor", GL.GL_VENDOR), ("gl_renderer", GL.GL_RENDERER),
                             ("gl_version", GL.GL_VERSION))}
    except Exception as err:  # informational only
        return {"gl_vendor": "", "gl_renderer": f"unknown ({err})", "gl_version": ""}


def gl_info() -> dict[str, str]:
    """Renderer and GL strings for provenance (after a renderer exists)."""
    import pyrender
    info = {"renderer": f"pyrender {getattr(pyrender, '__version__', '?')} (EGL offscreen)",
            "pyopengl_platform": os.environ.get("PYOPENGL_PLATFORM", "")}
    info.update(_GL_INFO)
    return info


_SHARED_TEXTURE: list[type] = []


def _shared_texture_class(pyrender) -> type:
    """A pyrender.Texture that keeps a uint8 RGB source as given (a view, not a copy).

    pyrender's own copies every source twice over (``astype``, then a channel pick):
    for a ground of 60 M texels that was 180 MB held for the life of the scene on top of
    the world's texture. The bytes uploaded to GL are the same (pyrender flips and
    flattens the source into a contiguous buffer at upload either way).
    """
    if not _SHARED_TEXTURE:
        class SharedTexture(pyrender.Texture):
            @property
            def source(self):
                return self._source

            @source.setter
            def source(self, value):
                if (isinstance(value, np.ndarray) and value.dtype == np.uint8 and value.ndim == 3
                        and value.shape[2] == 3 and self.source_channels == "RGB"):
                    self._source = value
                    self._is_transparent = False
                else:
                    pyrender.Texture.source.fset(self, value)

        _SHARED_TEXTURE.append(SharedTexture)
    return _SHARED_TEXTURE[0]


def _textured_material(pyrender, image: np.ndarray, *, repeat: bool):
    wrap = 10497 if repeat else 33071  # GL_REPEAT, GL_CLAMP_TO_EDGE
    sampler = pyrender.Sampler(magFilter=9729, minFilter=9987, wrapS=wrap, wrapT=wrap)  # LINEAR, LINEAR_MIPMAP_LINEAR
    tex = _shared_texture_class(pyrender)(source=image, source_channels="RGB", sampler=sampler)
    return pyrender.MetallicRoughnessMaterial(baseColorTexture=tex, metallicFactor=0.0, roughnessFactor=1.0)


def _colour_primitive(pyrender, mesh: dict, rgb: tuple[int, int, int]):
    n = mesh["positions"].shape[0]
    col = np.tile(np.array([[rgb[0] / 255.0, rgb[1] / 255.0, rgb[2] / 255.0, 1.0]], np.float32), (n, 1))
    mat = pyrender.MetallicRoughnessMaterial(metallicFactor=0.0, roughnessFactor=1.0)
    return pyrender.Primitive(positions=mesh["positions"], normals=mesh["normals"], color_0=col,
                              indices=mesh["indices"], material=mat)


def _ground_tiles(pyrender, world: World) -> list:
    """The ground as quads of at most MAX_TEXTURE_PX texels a side, one texture each."""
    tex = world.ground_texture
    ht, wt = tex.shape[:2]
    x0, y0 = world.extent_m[:2]
    texel = world.texel_m
    step = MAX_TEXTURE_PX  # a multiple of 4, as GL's row alignment wants
    prims = []
    nrm = np.tile(np.array([[0, 0, 1]], np.float32), (4, 1))
    idx = np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
    # pyrender uploads an image's first row at t = 1; our row r lies at y0 + (r + 0.5) texel,
    # so t runs from 1 at a tile's low y to 0 at its high y
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
    for r0 in range(0, ht, step):
        for c0 in range(0, wt, step):
            tile = tex[r0:r0 + step, c0:c0 + step]  # a view: the texture keeps it, uploads a copy
            xa, xb = x0 + c0 * texel, x0 + (c0 + tile.shape[1]) * texel
            ya, yb = y0 + r0 * texel, y0 + (r0 + tile.shape[0]) * texel
            pos = np.array([[xa, ya, 0], [xb, ya, 0], [xb, yb, 0], [xa, yb, 0]], np.float32)
            prims.append(pyrender.Primitive(positions=pos, normals=nrm, texcoord_0=uv, indices=idx,
                                            material=_textured_material(pyrender, tile, repeat=False)))
    return prims


class SceneRenderer:
    """A pyrender scene for one sequence: ground, buildings, vehicles and a camera.

    Parameters
    ----------
    spec : SceneSpec
    world : World
    vehicles : list of VehiclePath
    K : (3, 3) intrinsics with pixel centres at integer coordinates
    view_size_px : (width, height) of the renders when not the image's (a band of rows of a
        rolling shutter, a canvas larger than the image for lens distortion); see :meth:`render_view`
    """

    def __init__(self, spec, world: World, vehicles, K: np.ndarray, *, znear_m: float, zfar_m: float,
                 view_size_px: tuple[int, int] | None = None):
        pyrender = _pyrender()
        self.width_px, self.height_px = view_size_px or (spec.image.width_px, spec.image.height_px)
        self.renderer = get_renderer(self.width_px, self.height_px)
        self.flat = spec.photometry.lighting == "flat"
        ambient = (1.0, 1.0, 1.0) if self.flat else (0.35, 0.35, 0.35)
        self.scene = pyrender.Scene(bg_color=(0.0, 0.0, 0.0, 1.0), ambient_light=ambient)

        self.scene.add(pyrender.Mesh(_ground_tiles(pyrender, world)))

        if world.buildings:
            roof_mat = _textured_material(pyrender, world.building_texture, repeat=True)
            # walls darker than roofs, so that flat shading still shows the building's edges
            wall_tex = (world.building_texture.astype(np.float32) * 0.6).astype(np.uint8)
            wall_mat = _textured_material(pyrender, wall_tex, repeat=True)
            scale_m = world.building_texture.shape[0] * world.texel_m
            prims = []
            for b in world.buildings:
                m = box_mesh(b, uv_scale_m=scale_m)
                # box_mesh's triangles: 8 walls (+-x, +-y), 2 bottom, 2 top
                for tris, mat in ((m["indices"][:8], wall_mat), (m["indices"][10:12], roof_mat)):
                    prims.append(pyrender.Primitive(positions=m["positions"], normals=m["normals"],
                                                    texcoord_0=m["texcoords"], indices=tris, material=mat))
            self.scene.add(pyrender.Mesh(prims))

        self.vehicle_nodes = []
        for v in vehicles:
            body, cabin = vehicle_boxes(*v.size_m)
            prims = [_colour_primitive(pyrender, box_mesh(body), v.body_rgb),
                     _colour_primitive(pyrender, box_mesh(cabin), v.cabin_rgb)]
            self.vehicle_nodes.append(self.scene.add(pyrender.Mesh(prims), pose=np.eye(4)))

        fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
        # pyrender puts pixel centres at half-integers: shift the principal point by half a pixel
        cam = pyrender.IntrinsicsCamera(fx, fy, cx + 0.5, cy + 0.5, znear=znear_m, zfar=zfar_m)
        self.camera_node = self.scene.add(cam, pose=np.eye(4))
        self.flags = pyrender.RenderFlags.FLAT if self.flat else pyrender.RenderFlags.NONE
        if not self.flat:
            ph = spec.photometry
            el, az = math.radians(ph.sun_elevation_deg), math.radians(ph.sun_azimuth_deg)
            to_sun = np.array([math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el)])
            z = to_sun  # a light shines along its -z
            x = np.cross([0.0, 0.0, 1.0], z)
            x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-9 else np.array([1.0, 0, 0])
            y = np.cross(z, x)
            pose = np.eye(4)
            pose[:3, :3] = np.stack([x, y, z], axis=1)
            self.scene.add(pyrender.DirectionalLight(color=np.ones(3), intensity=2.5), pose=pose)
            if ph.shadows:
                self.flags |= pyrender.RenderFlags.SHADOWS_DIRECTIONAL

    def render(self, R_wc: np.ndarray, C_w: np.ndarray, vehicle_poses: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Render one frame: ``(rgb (H, W, 3) uint8, depth (H, W) float32 metres along z, 0 = nothing)``."""
        pose = np.eye(4)
        pose[:3, :3] = R_wc
        pose[:3, 3] = C_w
        self.scene.set_pose(self.camera_node, pose @ _CV_TO_GL)
        for node, M in zip(self.vehicle_nodes, vehicle_poses):
            self.scene.set_pose(node, M)
        rgb, depth = self.renderer.render(self.scene, flags=self.flags)
        return np.ascontiguousarray(rgb[..., :3]), depth

    def render_view(self, R_wc: np.ndarray, C_w: np.ndarray, vehicle_poses: list[np.ndarray], *,
                    cx_px: float, cy_px: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`render` with the principal point at ``(cx_px, cy_px)`` (integer pixel centres).

        An off-axis view: a band of rows ``r0..`` of a taller image is the same camera with
        ``cy - r0``; a canvas with a border of m pixels has ``cx + m, cy + m``.
        """
        cam = self.camera_node.camera
        cam.cx, cam.cy = cx_px + 0.5, cy_px + 0.5  # pyrender's pixel centres are at half-integers
        return self.render(R_wc, C_w, vehicle_poses)
