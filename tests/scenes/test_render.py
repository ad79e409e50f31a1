"""The renderer's own framebuffer read-back against pyrender's."""

from __future__ import annotations

import numpy as np
import pytest

from scenes import load_scene_spec
from scenes.generate import SceneGenerator

pytestmark = pytest.mark.gl


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
    assert depth.dtype == np.float32
    np.testing.assert_array_equal(depth, depth_ref)
    assert (depth > 0).mean() > 0.5
