"""scenes.render: what the GL renderer draws, checked against the camera geometry, and its own
framebuffer read-back against pyrender's."""

from __future__ import annotations

import numpy as np
import pytest

from scenes import load_scene_spec
from scenes.generate import SceneGenerator
from scenes.render import gl_info

pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def generator():
    bare = {"world.buildings.count": 0, "world.trees.density_per_ha": 0.0, "world.trees.wood_density_per_ha": 0.0,
            "world.trees.hedge_fraction": 0.0}
    return SceneGenerator(load_scene_spec("tiny", {"image.n_frames": 2, **bare}))


def test_a_nadir_view_of_flat_ground_has_the_altitude_as_depth(generator):
    R, C = generator.path.R[0], generator.path.C[0]
    rgb, depth = generator.renderer.render(R, C, generator.vehicle_matrices(0.0))
    h, w = generator.spec.image.height_px, generator.spec.image.width_px
    assert rgb.shape == (h, w, 3) and rgb.dtype == np.uint8 and depth.shape == (h, w)
    ground = depth > 0
    assert ground.mean() > 0.99  # nothing but the scene in view
    # z-depth of a flat ground plane seen (almost) straight down is the height above it at every pixel
    np.testing.assert_allclose(np.median(depth[ground]), C[2], rtol=0.01)
    assert rgb.std() > 5  # textured, not one flat colour


def test_an_off_axis_view_is_the_same_image_shifted_by_whole_rows(generator):
    """What the rolling shutter's bands rely on: principal point cy - r0 renders rows r0.. of the image."""
    R, C = generator.path.R[0], generator.path.C[0]
    K = generator.path.K
    poses = generator.vehicle_matrices(0.0)
    full, _ = generator.renderer.render_view(R, C, poses, cx_px=float(K[0, 2]), cy_px=float(K[1, 2]))
    r0 = 20
    band, _ = generator.renderer.render_view(R, C, poses, cx_px=float(K[0, 2]), cy_px=float(K[1, 2]) - r0)
    diff = np.abs(full[r0:].astype(int) - band[:-r0].astype(int))
    assert np.mean(diff) < 0.5 and np.mean(diff > 8) < 0.005, (np.mean(diff), np.mean(diff > 8))


def test_gl_info_names_the_renderer(generator):
    info = gl_info()
    assert "pyrender" in info["renderer"] and info["pyopengl_platform"] == "egl"


@pytest.mark.parametrize("light", ["flat", "sun"])
def test_frame_read_back_gives_pyrenders_colour_and_depth_exactly(light):
    # scenes.render replaces pyrender's read-back (nearest-filter resolve, in-place depth);
    # the pixels and the depth must be the ones pyrender's own gives
    spec = load_scene_spec("tiny", overrides={"image.n_frames": 2, "light.mode": light,
                                              "camera.tilt_deg": 35.0, "world.buildings.count": 3})
    gen = SceneGenerator(spec)
    inner = gen.renderer.renderer._renderer
    ours = inner._read_main_framebuffer
    assert ours is not type(inner)._read_main_framebuffer.__get__(inner)
    args = (gen.path.R[1], gen.path.C[1], gen.vehicle_matrices(float(gen.path.t_s[1])))
    try:
        rgb, depth = gen.renderer.render(*args)
        del inner._read_main_framebuffer  # pyrender's method again
        rgb_ref, depth_ref = gen.renderer.render(*args)
    finally:
        inner._read_main_framebuffer = ours
    assert rgb.dtype == np.uint8 and rgb.shape == rgb_ref.shape and rgb.flags.c_contiguous
    np.testing.assert_array_equal(rgb, rgb_ref)
    # a motion-blur sub-frame asks for colour only: the same pixels, no depth read back
    rgb_only, none = gen.renderer.render(*args, depth=False)
    assert none is None
    np.testing.assert_array_equal(rgb_only, rgb_ref)
    assert gen.renderer.render(*args)[1] is not None  # the next render reads depth again
    assert depth.dtype == np.float32
    np.testing.assert_array_equal(depth, depth_ref)
    assert (depth > 0).mean() > 0.5


def _bands_of(gen, r0: int, rows: int):
    """Render rows r0..r0+rows of frame 1 (a band view) with culling on and with every vehicle drawn."""
    from scenes.render import SceneRenderer

    R, C = gen.path.R[1], gen.path.C[1]
    K = gen.path.K
    Ms = gen.vehicle_matrices(float(gen.path.t_s[1]))
    band = SceneRenderer(gen.spec, gen.world, gen.vehicles, K, znear_m=0.5, zfar_m=5000.0,
                         view_size_px=(gen.spec.image.width_px, rows))
    view = {"cx_px": float(K[0, 2]), "cy_px": float(K[1, 2]) - r0}
    band.render_view(R, C, Ms, **view)  # draws the shadow map (sun), with every vehicle
    culled = band.render_view(R, C, Ms, **view, shadow_map=False)
    hidden = band.culled
    band._in_view = lambda *a, **k: np.ones(len(Ms), bool)  # every road user drawn
    drawn = band.render_view(R, C, Ms, **view, shadow_map=False)
    assert band.culled == 0
    return culled, drawn, hidden


@pytest.mark.parametrize("light", ["flat", "sun"])
def test_vehicles_outside_a_band_are_not_drawn_and_the_pixels_are_the_same(light):
    spec = load_scene_spec("tiny", overrides={"image.n_frames": 2, "light.mode": light, "vehicles.count": 12,
                                              "vehicles.parked_fraction": 0.0})
    gen = SceneGenerator(spec)
    hidden_any = 0
    for r0 in range(0, spec.image.height_px, 16):
        (rgb, depth), (rgb_ref, depth_ref), hidden = _bands_of(gen, r0, 16)
        np.testing.assert_array_equal(rgb, rgb_ref)
        np.testing.assert_array_equal(depth, depth_ref)
        hidden_any += hidden
    assert hidden_any > 0  # the culling did hide vehicles (else the test shows nothing)


def test_a_reused_shadow_map_is_the_one_drawn_and_another_scene_forces_a_new_one():
    spec = load_scene_spec("tiny", overrides={"image.n_frames": 3, "light.mode": "sun", "light.shadows": True,
                                              "world.buildings.count": 3})
    gen = SceneGenerator(spec)
    other = SceneGenerator(load_scene_spec("tiny", overrides={"image.n_frames": 3, "light.mode": "sun",
                                                               "seed": 99}))
    args = (gen.path.R[1], gen.path.C[1], gen.vehicle_matrices(float(gen.path.t_s[1])))
    fresh = gen.renderer.render(*args)
    reused = gen.renderer.render(*args, shadow_map=False)
    np.testing.assert_array_equal(fresh[0], reused[0])
    # the other scene's render frees this scene's map: a reuse asked for now draws a new one
    other.renderer.render(other.path.R[0], other.path.C[0], other.vehicle_matrices(0.0))
    after = gen.renderer.render(*args, shadow_map=False)
    np.testing.assert_array_equal(fresh[0], after[0])
    # the switch is off again once a render returns: the next caller's render draws its own map
    inner = gen.renderer.renderer._renderer
    assert inner.skip_shadow_pass is False


def test_meshes_at_one_distance_are_drawn_in_the_order_of_their_names_whatever_the_set_order(generator):
    """Two coplanar quads at the world origin overlap exactly: the first drawn wins the depth test. pyrender's own
    order of such nodes follows its set of nodes (memory addresses: it changed from process to process, and two
    renders of one spec differed in a few pixels, which H.264 spread over whole blocks); ours follows the names."""
    import pyrender

    inner = generator.renderer.renderer._renderer
    quad = np.array([[-500, -500, 0], [500, -500, 0], [500, 500, 0], [-500, 500, 0]], np.float32)

    def flat():
        return pyrender.Mesh([pyrender.Primitive(positions=quad, indices=np.array([[0, 1, 2], [0, 2, 3]]))])

    orders = set()
    for names in (("a", "b", "c"), ("c", "b", "a"), ("b", "c", "a")):
        scene = pyrender.Scene()
        scene.add(pyrender.PerspectiveCamera(yfov=1.0), pose=np.eye(4))
        for name in names:
            scene.add(flat(), name=name)
        scene.main_camera_node = next(iter(scene.camera_nodes))
        orders.add(tuple(n.name for n in inner._sorted_mesh_nodes(scene)))
    assert orders == {("a", "b", "c")}
