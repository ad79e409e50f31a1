"""Offscreen rendering with pyrender through EGL: the only module that touches OpenGL.

One ``OffscreenRenderer`` per image size per process, cached in a module-level
dict and never deleted: deleting one tears EGL down for the whole process.
Never fork a process that holds a renderer (use the spawn start method).
"""

from __future__ import annotations

import atexit
import os
import sys
import weakref

import numpy as np

from scenes import car_paint
from scenes.traffic import PAINTED_CLASSES, vehicle_parts
from scenes.vegetation import CROWN_BASES, sun_shading, trunk_size, unit_cone
from scenes.world import MAX_TEXTURE_PX, Box, World, box_mesh, sun_direction

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
        _install_frame_reader(r)
        _install_shadow_switch(r)
        _install_draw_order(r)
        _RENDERERS[key] = r
        if not _GL_INFO:
            _GL_INFO.update(_query_gl_strings())
    return r


def _install_frame_reader(offscreen) -> None:
    """Replace pyrender's framebuffer read-back of ``offscreen`` by :func:`_read_frame` (same arrays).

    pyrender resolves the 4x multisampled colour with a linear-filtered blit and converts the
    depth with boolean-mask indexing and several full-image temporaries; both cost about 3 ms a
    640x480 frame on llvmpipe. The resolve averages the samples whatever the filter (the pixels
    are the same: tests/scenes/test_render.py, and by hand on every preset), and
    the depth is the same float32 expression computed in place.
    """
    import types

    inner = getattr(offscreen, "_renderer", None)
    original = getattr(inner, "_read_main_framebuffer", None)
    if original is None:  # another pyrender: keep its read-back
        return

    def read(self, scene, flags):
        from pyrender.constants import RenderFlags

        if flags & (RenderFlags.DEPTH_ONLY | RenderFlags.RGBA | RenderFlags.SEG) or sys.platform == "darwin":
            return original(scene, flags)
        cam = scene.main_camera_node.camera
        return _read_frame(self, cam.znear, cam.zfar, depth=not self.skip_depth)

    inner.skip_depth = False  # SceneRenderer.render(depth=False): colour only, depth None
    inner._read_main_framebuffer = types.MethodType(read, inner)


def _install_shadow_switch(offscreen) -> None:
    """Let :meth:`SceneRenderer.render` skip pyrender's shadow-map pass (``inner.skip_shadow_pass``).

    pyrender renders every shadow map again on every call: the whole world into a 2048 x 2048
    depth texture, for each band and motion-blur sub-frame of a frame. The forward pass samples
    the light's shadow texture as it stands, so a map drawn once per frame serves its renders.
    """
    import types

    inner = getattr(offscreen, "_renderer", None)
    original = getattr(inner, "_shadow_mapping_pass", None)
    if original is None:
        return
    inner.skip_shadow_pass = False

    def shadow_pass(self, scene, light_node, flags):
        if not self.skip_shadow_pass:
            original(scene, light_node, flags)

    inner._shadow_mapping_pass = types.MethodType(shadow_pass, inner)


def _install_draw_order(offscreen) -> None:
    """Draw the meshes of ``offscreen`` in an order fixed by the scene, not by memory addresses.

    pyrender sorts the mesh nodes by the distance of their origin from the camera, a stable sort of
    its set of nodes: nodes at one distance (every static mesh of a world lies at the origin) keep the
    set's order, which follows the nodes' ids, so it changes from process to process. Where two
    meshes meet at one depth (a roof's edge on its wall, a crown on a roof) the first drawn wins the
    depth test: two renders of one spec differed in 3-50 pixels a frame, and a video codec carries
    such a change on to whole blocks of the frames after it (H.264 city, 40 frames: a mean of 1.2 grey
    levels). Ties are broken by the node's name (:class:`SceneRenderer` names every node it adds).
    """
    import types

    inner = getattr(offscreen, "_renderer", None)
    if getattr(inner, "_sorted_mesh_nodes", None) is None:
        return

    def sorted_mesh_nodes(self, scene):
        cam = scene.get_pose(scene.main_camera_node)[:3, 3]

        def key(node):
            return (-float(np.linalg.norm(scene.get_pose(node)[:3, 3] - cam)), node.name or "")

        nodes = sorted(scene.mesh_nodes, key=key)
        return [n for n in nodes if not n.mesh.is_transparent] + [n for n in nodes if n.mesh.is_transparent]

    inner._sorted_mesh_nodes = types.MethodType(sorted_mesh_nodes, inner)


def _read_frame(inner, znear: float, zfar: float | None, *, depth: bool = True
                ) -> tuple[np.ndarray, np.ndarray | None]:
    """Colour (H, W, 3) uint8 and linear depth (H, W) float32 (0 = nothing; None when ``depth`` is
    False: neither blitted nor read) of pyrender's main framebuffer.

    The depth is pyrender's: NDC ``z = 2 d - 1`` of the window depth ``d``, then
    ``2 n f / (f + n - z (f - n))`` (``2 n / (1 - z)`` without a far plane), float32 with the
    scalars rounded to float32 as numpy does, 0 where ``d = 1`` (nothing drawn); rows flipped to
    top-down.
    """
    from OpenGL import GL

    width, height = inner._main_fb_dims
    GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, inner._main_fb_ms)
    GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, inner._main_fb)
    GL.glBlitFramebuffer(0, 0, width, height, 0, 0, width, height, GL.GL_COLOR_BUFFER_BIT, GL.GL_NEAREST)
    if not depth:
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, inner._main_fb)
        GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
        raw = np.empty((height, width, 3), np.uint8)
        GL.glReadPixels(0, 0, width, height, GL.GL_RGB, GL.GL_UNSIGNED_BYTE, raw.ctypes.data)
        return raw[::-1].copy(), None
    GL.glBlitFramebuffer(0, 0, width, height, 0, 0, width, height, GL.GL_DEPTH_BUFFER_BIT, GL.GL_NEAREST)
    GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, inner._main_fb)
    GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
    d = np.empty((height, width), np.float32)
    GL.glReadPixels(0, 0, width, height, GL.GL_DEPTH_COMPONENT, GL.GL_FLOAT, d.ctypes.data)
    raw = np.empty((height, width, 3), np.uint8)
    GL.glReadPixels(0, 0, width, height, GL.GL_RGB, GL.GL_UNSIGNED_BYTE, raw.ctypes.data)
    d = d[::-1]
    depth = np.multiply(d, np.float32(2.0))
    depth -= np.float32(1.0)
    if zfar is None:
        # 2 n / (1 - z)
        np.subtract(np.float32(1.0), depth, out=depth)
        np.divide(np.float32(2 * znear), depth, out=depth)
    else:
        # 2 n f / (f + n - z (f - n))
        depth *= np.float32(zfar - znear)
        np.subtract(np.float32(zfar + znear), depth, out=depth)
        np.divide(np.float32(2.0 * znear * zfar), depth, out=depth)
    depth[d == 1.0] = 0.0
    return raw[::-1].copy(), depth


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


# flat light has no shading: faces are darkened by these factors instead, as a sun high in the
# south-east would (top faces full, walls less); sun light shades them itself
FLAT_FACE_SHADE = {"top": 1.0, "side": 0.72}
CROWN_SEGMENTS = 10
SHADOW_QUAD_LIFT_M = 0.03  # a vehicle's flat-light shadow lies this far above the ground (ground truth: ground)
CULL_MARGIN_PX = 4.0  # a vehicle this far outside the view is still drawn (multisampling, rounding)


def _face_colours(mesh: dict, rgb, *, flat: bool) -> np.ndarray:
    """Per-vertex RGBA (n, 4) float32: ``rgb`` darkened on walls under flat light (by the face normal)."""
    col = np.tile(np.array([[rgb[0] / 255.0, rgb[1] / 255.0, rgb[2] / 255.0, 1.0]], np.float32),
                  (mesh["positions"].shape[0], 1))
    col[:, :3] = np.minimum(col[:, :3], 1.0)
    if flat:
        up = mesh["normals"][:, 2]
        col[:, :3] *= np.where(up > 0.5, FLAT_FACE_SHADE["top"], FLAT_FACE_SHADE["side"])[:, None]
    return col if flat else _to_linear(col)


def _to_linear(col: np.ndarray) -> np.ndarray:
    """Vertex colours (n, 4) for sun light: pyrender multiplies the lit colour in linear light by the
    vertex colour and then writes ``c ** (1 / 2.2)``, so a colour meant as seen (sRGB) goes in as
    ``c ** 2.2`` (textures it decodes itself; flat light writes colours as they are)."""
    out = np.array(col, np.float32, copy=True)
    out[:, :3] **= 2.2
    return out


def _merge(meshes: list[dict]) -> dict:
    out, base = {k: [] for k in meshes[0]}, 0
    for m in meshes:
        for k, v in m.items():
            out[k].append(v + base if k == "indices" else v)
        base += m["positions"].shape[0]
    return {k: np.concatenate(v) for k, v in out.items()}


def _placed(mesh: dict, yaw: float, at_xy) -> dict:
    c, s = np.cos(yaw), np.sin(yaw)
    Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], np.float32)
    out = dict(mesh)
    out["positions"] = mesh["positions"] @ Rz.T + np.array([at_xy[0], at_xy[1], 0.0], np.float32)
    out["normals"] = mesh["normals"] @ Rz.T
    return out


def _building_prims(pyrender, world: World, *, flat: bool) -> list:
    """All buildings in two draws: walls, and roofs with their parapets and roof units (tinted per building).

    Each draw costs about as much CPU as a small scene in pyrender, so parts are merged, not added."""
    walls, roofs = [], []
    for b, parapets in [(b, world.parapet_tints) for b in world.buildings] + [(b, None) for b in world.overpasses]:
        tint = np.asarray(world.roof_tints[b.roof_variant])
        for p, part in enumerate(b.parts):
            m = _placed(box_mesh(part, uv_scale_m=12.8), b.yaw_rad, b.centre[:2])
            tri = m["indices"]
            if p == 0:  # the block: walls (faces 0-3) and roof (face 5); its floor is never seen
                walls.append({**m, "indices": tri[:8], "colours": _face_colours(m, (255, 255, 255), flat=flat)})
                roofs.append({**m, "indices": tri[10:12], "colours": _face_colours(m, 255 * tint, flat=flat)})
            else:  # parapet (darker) and roof units (lighter; every third dark: skylights, solar panels)
                if p <= 4 and parapets is not None:  # a building's parapet (a footbridge's parts keep its tint)
                    rgb = 255 * np.asarray(parapets[b.roof_variant])
                else:
                    rgb = 255 * (0.85 if p <= 4 else (0.5 if p % 3 == 0 else 1.25)) * tint
                roofs.append({**m, "indices": np.concatenate([tri[:8], tri[10:12]]),
                              "colours": _face_colours(m, np.minimum(255, rgb), flat=flat)})
    prims = []
    for parts, tex in ((walls, world.wall_textures[0]), (roofs, world.roof_textures[0])):
        m = _merge(parts)
        prims.append(pyrender.Primitive(positions=m["positions"], normals=m["normals"], texcoord_0=m["texcoords"],
                                        color_0=m["colours"], indices=m["indices"],
                                        material=_textured_material(pyrender, tex, repeat=True)))
    return prims


def _unit_crown() -> dict:
    """A unit crown, instanced and scaled per tree: a top, a ring of CROWN_SEGMENTS at 50 deg, a ring at the
    equator and a bottom (4 x CROWN_SEGMENTS triangles; an icosphere would cost twice as many and llvmpipe
    pays per vertex of every instance), with top-down UVs."""
    n = CROWN_SEGMENTS
    a = 2 * np.pi * np.arange(n) / n
    upper = np.column_stack([0.64 * np.cos(a + np.pi / n), 0.64 * np.sin(a + np.pi / n), np.full(n, 0.77)])
    equator = np.column_stack([np.cos(a), np.sin(a), np.zeros(n)])
    v = np.vstack([[0, 0, 1.0], upper, equator, [0, 0, -1.0]]).astype(np.float32)
    top, bottom = 0, 2 * n + 1
    faces = []
    for k in range(n):
        u0, u1 = 1 + k, 1 + (k + 1) % n
        e0, e1 = 1 + n + k, 1 + n + (k + 1) % n
        faces += [(top, u0, u1), (u0, e0, e1), (u0, e1, u1), (bottom, e1, e0)]
    return {"positions": v, "normals": v / np.linalg.norm(v, axis=1, keepdims=True),
            "indices": np.asarray(faces, np.uint32), "texcoords": 0.5 + 0.5 * v[:, :2]}


def _tree_meshes(pyrender, world: World, *, flat: bool, sun: np.ndarray, ambient: float) -> list:
    """Every crown lobe and conifer cone in one draw (a merged mesh: per-vertex colour, so each variant and
    each tree its own tint, which instancing cannot give; llvmpipe pays per vertex either way, pyrender
    per draw), trunks instanced once, and the woods' canopies in one draw. Under flat light the sun's
    shading is baked into the vertex colours (trees are never turned, so the baked light keeps its
    direction)."""
    crown, cone = _unit_crown(), unit_cone(CROWN_SEGMENTS)

    def shade(normals):
        if not flat:
            return np.ones(len(normals), np.float32)
        return sun_shading(normals, sun, ambient)

    meshes = []
    parts = []
    for t in world.trees:
        unit = cone if t.conifer else crown
        tint = np.asarray(CROWN_BASES[t.variant], np.float32) / 255.0
        for dx, dy, z, rx, ry, rz in t.lobes:
            scale = np.array([rx, ry, rz], np.float32)
            nrm = unit["normals"] / scale  # normals of a scaled surface: by the inverse scale
            nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
            col = np.empty((len(nrm), 4), np.float32)
            col[:, :3] = tint * shade(nrm)[:, None]
            col[:, 3] = 1.0
            if not flat:
                col = _to_linear(col)
            parts.append({"positions": unit["positions"] * scale + np.array([t.x_m + dx, t.y_m + dy, z], np.float32),
                          "normals": nrm, "texcoords": unit["texcoords"], "colours": col, "indices": unit["indices"]})
    if parts:
        m = _merge(parts)
        meshes.append(pyrender.Mesh([pyrender.Primitive(
            positions=m["positions"], normals=m["normals"], texcoord_0=m["texcoords"], color_0=m["colours"],
            indices=m["indices"], material=_textured_material(pyrender, world.crown_textures[0], repeat=False))]))
    trunks = [t for t in world.trees if not t.bush]
    if trunks:
        unit = box_mesh(Box(centre=(0.0, 0.0, 0.0), size=(1.0, 1.0, 1.0)))
        poses = np.zeros((len(trunks), 4, 4), np.float32)
        for n, t in enumerate(trunks):
            w, h = trunk_size(t)
            poses[n] = np.diag([w, w, h, 1.0])
            poses[n, :3, 3] = (t.x_m, t.y_m, h / 2)
        col = _face_colours(unit, (92, 74, 56), flat=flat)
        mat = pyrender.MetallicRoughnessMaterial(metallicFactor=0.0, roughnessFactor=1.0)
        meshes.append(pyrender.Mesh([pyrender.Primitive(positions=unit["positions"], normals=unit["normals"],
                                                        color_0=col, indices=unit["indices"], material=mat,
                                                        poses=poses)]))
    if world.canopies:
        parts = []
        for c in world.canopies:
            col = np.column_stack([c["tint"] * shade(c["normals"])[:, None], np.ones(len(c["tint"]), np.float32)])
            parts.append({k: c[k] for k in ("positions", "normals", "texcoords", "indices")}
                         | {"colours": col if flat else _to_linear(col)})
        m = _merge(parts)
        meshes.append(pyrender.Mesh([pyrender.Primitive(
            positions=m["positions"], normals=m["normals"], texcoord_0=m["texcoords"], color_0=m["colours"],
            indices=m["indices"], material=_textured_material(pyrender, world.canopy_texture, repeat=True))]))
    return meshes


def _road_user_parts(v, *, flat: bool) -> list[dict]:
    """Mesh parts (positions, normals, indices, colours) of road user ``v`` in its own frame: the boxes of
    :func:`scenes.traffic.vehicle_parts` (the truth's shape), coloured. Cars, vans, trucks and buses are
    painted (:func:`scenes.car_paint.vehicle_parts`): the tops of their body-coloured boxes glossy, with
    the sky highlight painted under flat light; glass and cargo matt. Motorbikes, cyclists and
    pedestrians are plain boxes shaded like buildings."""
    boxes_rgb = vehicle_parts(v)
    if v.vclass not in PAINTED_CLASSES:
        return [{**m, "colours": _face_colours(m, rgb, flat=flat)} for m, rgb in
                ((box_mesh(b), rgb) for b, rgb in boxes_rgb)]
    boxes, colours = zip(*boxes_rgb)
    body = tuple(int(c) for c in v.body_rgb)
    glossy = tuple(tuple(int(c) for c in rgb) == body for rgb in colours)
    parts = car_paint.vehicle_parts(boxes, colours, glossy=glossy, paint_highlight=flat,
                                    side_shade=FLAT_FACE_SHADE["side"] if flat else 1.0)
    return parts if flat else [{**p, "colours": _to_linear(p["colours"])} for p in parts]


class SceneRenderer:
    """A pyrender scene for one sequence: ground, buildings, trees, vehicles (and their shadows), a camera.

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
        light = spec.light
        self.flat = light.mode == "flat"
        sun = sun_direction(light.sun_elevation_deg, light.sun_azimuth_deg)
        # sun light: pyrender mixes in linear light and writes sRGB, so sky light ``ambient`` (the
        # brightness of shadow relative to sunlit ground, as seen in the image) is ambient^2.2 linear
        amb_lin = light.ambient ** 2.2
        ambient = (1.0, 1.0, 1.0) if self.flat else (amb_lin,) * 3
        self.scene = pyrender.Scene(bg_color=(0.0, 0.0, 0.0, 1.0), ambient_light=ambient)

        # every mesh node is named: the name breaks ties in the draw order (_install_draw_order)
        self.scene.add(pyrender.Mesh(_ground_tiles(pyrender, world)), name="0-ground")
        if world.buildings or world.overpasses:
            self.scene.add(pyrender.Mesh(_building_prims(pyrender, world, flat=self.flat)), name="1-buildings")
        for i, mesh in enumerate(_tree_meshes(pyrender, world, flat=self.flat, sun=sun, ambient=light.ambient)):
            self.scene.add(mesh, name=f"2-trees-{i:04d}")

        # All vehicles are two draws: the parked ones one static mesh, the moving ones one mesh whose
        # vertices are placed on the CPU for every render (pyrender costs about 0.5 ms of CPU a draw,
        # and a city has a hundred road users: one draw each cost more than the rest of the scene).
        # Each road user is its boxes (scenes.traffic.vehicle_parts) with vertex colours. Under flat
        # light it also carries its shadow: a translucent dark quad (vertex alpha, blended), its
        # footprint moved away from the sun by the shadow of the car's middle height, turned into the
        # vehicle frame at mid-sequence (on a curve the shadow turns a little with the car). The quad
        # lies SHADOW_QUAD_LIFT_M above the ground, within the truth's depth tolerance: it is ground.
        # Ground truth is the motion field of surfaces, not the apparent motion of a shadow. Every
        # shadow quad comes before every body in its mesh, so the blending order cannot darken a car.
        self._pyrender = pyrender
        self._moving = [k for k, v in enumerate(vehicles) if not v.parked]
        self._moving_node = None
        shadow = self.flat and light.shadows
        away = -sun[:2] / max(1e-9, sun[2])
        t_mid_s = 0.5 * (spec.image.n_frames - 1) / spec.image.fps
        # one material for all road users (a draw each costs): glossy under sun light (car paint's
        # specular highlight; pedestrians' and cyclists' few pixels take it too), matt under flat light
        self._vehicle_material = pyrender.MetallicRoughnessMaterial(
            metallicFactor=0.0, roughnessFactor=1.0 if self.flat else car_paint.GLOSS_ROUGHNESS,
            alphaMode="BLEND" if shadow else "OPAQUE")
        parked_shadows, parked_bodies, moving_shadows, moving_bodies = [], [], [], []
        for k, v in enumerate(vehicles):
            parts = []
            if shadow:
                th = v.pose(t_mid_s)[2]
                c, s_ = np.cos(th), np.sin(th)
                off = np.array([[c, s_], [-s_, c]]) @ (away * 0.6 * v.size_m[2])
                L, W = v.size_m[0] + 0.2, v.size_m[1] + 0.2
                pos = np.array([[-L / 2, -W / 2, 0], [L / 2, -W / 2, 0], [L / 2, W / 2, 0], [-L / 2, W / 2, 0]],
                               np.float32) + np.array([off[0], off[1], SHADOW_QUAD_LIFT_M], np.float32)
                parts.append({"positions": pos, "normals": np.tile(np.float32([[0, 0, 1]]), (4, 1)),
                              "indices": np.array([[0, 1, 2], [0, 2, 3]], np.uint32),
                              "colours": np.tile(np.float32([[0, 0, 0, 1.0 - light.ambient]]), (4, 1))})
            parts += _road_user_parts(v, flat=self.flat)
            for p in parts:
                p["owner"] = np.full(len(p["positions"]), k, np.int64)
            if v.parked:
                M = v.matrix(0.0)
                parts = [{**p, "positions": (p["positions"] @ M[:3, :3].T + M[:3, 3]).astype(np.float32),
                          "normals": (p["normals"] @ M[:3, :3].T).astype(np.float32)} for p in parts]
                parked_shadows += parts[:1] if shadow else []
                parked_bodies += parts[1:] if shadow else parts
            else:
                moving_shadows += parts[:1] if shadow else []
                moving_bodies += parts[1:] if shadow else parts
        if parked_bodies:
            m = _merge(parked_shadows + parked_bodies)
            self.scene.add(pyrender.Mesh([pyrender.Primitive(positions=m["positions"], normals=m["normals"],
                                                             color_0=m["colours"], indices=m["indices"],
                                                             material=self._vehicle_material)]),
                           name="3-parked")
        self._moving_parts = _merge(moving_shadows + moving_bodies) if moving_bodies else None
        # the 8 corners of each moving road user's box (shadow quad included) in its own frame, for
        # culling: (V, 8, 3), zeros for parked ones (never culled: their mesh is one static draw)
        self._vehicle_corners = np.zeros((len(vehicles), 8, 3))
        if self._moving_parts is not None:
            m = self._moving_parts
            for k in self._moving:
                pts = m["positions"][m["owner"] == k].astype(np.float64)
                lo_hi = np.stack([pts.min(axis=0), pts.max(axis=0)])
                self._vehicle_corners[k] = [[bx, by, bz] for bx in lo_hi[:, 0] for by in lo_hi[:, 1]
                                            for bz in lo_hi[:, 2]]
        self.culled = 0  # moving road users left out of the last render (outside its view)

        fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
        # pyrender puts pixel centres at half-integers: shift the principal point by half a pixel
        cam = pyrender.IntrinsicsCamera(fx, fy, cx + 0.5, cy + 0.5, znear=znear_m, zfar=zfar_m)
        self.camera_node = self.scene.add(cam, pose=np.eye(4))
        self.flags = pyrender.RenderFlags.FLAT if self.flat else pyrender.RenderFlags.NONE
        self.has_shadow_maps = not self.flat and bool(light.shadows)  # pyrender draws them before each render
        if not self.flat:
            z = sun  # a light shines along its -z
            x = np.cross([0.0, 0.0, 1.0], z)
            x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-9 else np.array([1.0, 0, 0])
            y = np.cross(z, x)
            pose = np.eye(4)
            pose[:3, :3] = np.stack([x, y, z], axis=1)
            # sunlit flat ground = its base colour: (I sin(el) / pi) + ambient = 1 in linear light
            intensity = (1.0 - amb_lin) * np.pi / max(0.05, sun[2])
            self.scene.add(pyrender.DirectionalLight(color=np.ones(3), intensity=intensity), pose=pose)
            if light.shadows:
                self.flags |= pyrender.RenderFlags.SHADOWS_DIRECTIONAL

    def render(self, R_wc: np.ndarray, C_w: np.ndarray, vehicle_poses: list[np.ndarray], *,
               shadow_map: bool = True, depth: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Render one frame: ``(rgb (H, W, 3) uint8, depth (H, W) float32 metres along z, 0 = nothing)``;
        depth None with ``depth=False`` (a motion-blur sub-frame off the truth's instant: its depth is
        never used, and reading it back cost about half of the read-back).

        ``shadow_map=False`` reuses the shadow map the last render of this scene drew (the
        shadows of the vehicles where they were then; static shadows are the same): the sub-frames
        and bands of one frame share the map of its first render. Only the look of moving
        shadows depends on it, never the ground truth (shadows are light, not surfaces).
        """
        pose = np.eye(4)
        pose[:3, :3] = R_wc
        pose[:3, 3] = C_w
        self.scene.set_pose(self.camera_node, pose @ _CV_TO_GL)
        inner = getattr(self.renderer, "_renderer", None)
        switch = inner is not None and hasattr(inner, "skip_shadow_pass")
        # only while this scene was the last one drawn: rendering another scene frees this one's map
        skip = (switch and not shadow_map and self.has_shadow_maps
                and getattr(inner, "last_scene", lambda: None)() is self.scene)
        if self._moving_parts is not None:
            # a shadow map drawn now needs every vehicle; otherwise those outside the view are not drawn
            drawn = self._in_view(R_wc, C_w, vehicle_poses) if skip or not self.has_shadow_maps else None
            self._place_moving(vehicle_poses, drawn)
        if switch:
            inner.skip_shadow_pass = skip
        reader = inner is not None and hasattr(inner, "skip_depth")
        if reader:
            inner.skip_depth = not depth
        try:
            rgb, z = self.renderer.render(self.scene, flags=self.flags)
        finally:
            if switch:
                inner.skip_shadow_pass = False
                inner.last_scene = weakref.ref(self.scene)
            if reader:
                inner.skip_depth = False
        return np.ascontiguousarray(rgb[..., :3]), z

    def _place_moving(self, vehicle_poses: list[np.ndarray], drawn: np.ndarray | None = None) -> None:
        """Replace the moving vehicles' mesh by one with every vertex at its vehicle's pose, of the road
        users ``drawn`` (bool per vehicle; None: all of them)."""
        m = self._moving_parts
        owner, positions, normals, colours = m["owner"], m["positions"], m["normals"], m["colours"]
        indices = m["indices"]
        self.culled = 0
        if drawn is not None:
            keep = drawn[owner]
            self.culled = len(self._moving) - int(np.count_nonzero(drawn[self._moving]))
            if not keep.all():
                new_index = np.cumsum(keep) - 1
                tri = indices[keep[indices[:, 0]]]  # a triangle's vertices share their owner
                owner, positions, normals, colours = owner[keep], positions[keep], normals[keep], colours[keep]
                indices = new_index[tri].astype(np.uint32)
        if self._moving_node is not None:
            self.scene.remove_node(self._moving_node)
            self._moving_node = None
        if not len(indices):
            return
        M = np.asarray(vehicle_poses, np.float64)[owner]  # (n, 4, 4) per vertex
        pos = np.einsum("nij,nj->ni", M[:, :3, :3], positions.astype(np.float64)) + M[:, :3, 3]
        nrm = np.einsum("nij,nj->ni", M[:, :3, :3], normals.astype(np.float64))
        prim = self._pyrender.Primitive(positions=pos.astype(np.float32), normals=nrm.astype(np.float32),
                                        color_0=colours, indices=indices, material=self._vehicle_material)
        self._moving_node = self.scene.add(self._pyrender.Mesh([prim]), name="4-moving")

    def _in_view(self, R_wc: np.ndarray, C_w: np.ndarray, vehicle_poses: list[np.ndarray]) -> np.ndarray:
        """Which road users to draw (bool per vehicle): not those whose mesh (shadow quad included)
        projects wholly outside the view.

        llvmpipe pays for every vertex of the moving mesh, placed and uploaded for each render, and
        a band of a rolling shutter sees a few of the road users. The box of the mesh's corners is
        the hull of its image when all lie in front of the camera; a road user with a corner behind
        it is kept. The pixels are those of drawing every road user.
        """
        cam = self.camera_node.camera
        fx, fy, cx, cy = cam.fx, cam.fy, cam.cx - 0.5, cam.cy - 0.5
        Ms = np.asarray(vehicle_poses, np.float64)[: len(self._vehicle_corners)]
        world = np.einsum("vij,vkj->vki", Ms[:, :3, :3], self._vehicle_corners) + Ms[:, None, :3, 3]
        Xc = (world - np.asarray(C_w, np.float64)) @ np.asarray(R_wc, np.float64)  # R^T (X - C), per row
        z = Xc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = fx * Xc[..., 0] / z + cx
            y = fy * Xc[..., 1] / z + cy
        m = CULL_MARGIN_PX
        outside = ((x.max(axis=1) < -m) | (x.min(axis=1) > self.width_px - 1 + m)
                   | (y.max(axis=1) < -m) | (y.min(axis=1) > self.height_px - 1 + m))
        outside &= (z > 0).all(axis=1)
        return ~outside

    def render_view(self, R_wc: np.ndarray, C_w: np.ndarray, vehicle_poses: list[np.ndarray], *,
                    cx_px: float, cy_px: float, shadow_map: bool = True, depth: bool = True
                    ) -> tuple[np.ndarray, np.ndarray | None]:
        """:meth:`render` with the principal point at ``(cx_px, cy_px)`` (integer pixel centres).

        An off-axis view: a band of rows ``r0..`` of a taller image is the same camera with
        ``cy - r0``; a canvas with a border of m pixels has ``cx + m, cy + m``.
        """
        cam = self.camera_node.camera
        cam.cx, cam.cy = cx_px + 0.5, cy_px + 0.5  # pyrender's pixel centres are at half-integers
        return self.render(R_wc, C_w, vehicle_poses, shadow_map=shadow_map, depth=depth)
