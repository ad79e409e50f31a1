"""Every road-user class drawn on its exact boxes: cars, vans, trucks and buses painted (glossy
body-coloured tops with the sky highlight under flat light), motorbikes, cyclists and pedestrians plain."""

from __future__ import annotations

import numpy as np
import pytest

from scenes.car_paint import HIGHLIGHT
from scenes.motion import VehiclePath
from scenes.render import FLAT_FACE_SHADE, _road_user_parts
from scenes.traffic import CLASS_SIZES_M, CLASSES, PAINTED_CLASSES, vehicle_parts, vehicle_shape

BODY = (150, 36, 34)


def _user(cls: str) -> VehiclePath:
    size = tuple(float(np.mean(r)) for r in CLASS_SIZES_M[cls])
    return VehiclePath(vehicle_id=3, kind="parked", route_m=np.array([[0.0, 0.0], [10.0, 0.0]]), s0_m=5.0,
                       v0_mps=0.0, size_m=size, body_rgb=BODY, cabin_rgb=(34, 40, 48), vclass=cls)


@pytest.mark.parametrize("cls", CLASSES)
def test_each_class_is_drawn_within_its_truth_boxes_painted_where_it_applies(cls):
    v = _user(cls)
    parts = _road_user_parts(v, flat=True)
    boxes = vehicle_shape(v)
    assert len(parts) == len(boxes)
    body = np.array(BODY) / 255.0
    band = body + HIGHLIGHT * (1.0 - body)
    highlighted = 0
    for part, box, (_, rgb) in zip(parts, boxes, vehicle_parts(v)):
        lo = np.asarray(box.centre) - np.asarray(box.size) / 2
        hi = np.asarray(box.centre) + np.asarray(box.size) / 2
        p = part["positions"]
        assert (p >= lo - 1e-5).all() and (p <= hi + 1e-5).all()  # the truth's box, never beyond it
        up = part["normals"][:, 2] > 0.5
        assert np.isclose(p[up, 2], hi[2], atol=1e-5).all() and up.any()  # a top face, on the box's top
        col = part["colours"][:, :3]
        base = np.asarray(rgb) / 255.0
        walls = col[~up]
        np.testing.assert_allclose(walls, np.broadcast_to(base * FLAT_FACE_SHADE["side"], walls.shape), atol=1e-6)
        is_band = np.isclose(col[up], band, atol=1e-6).all(axis=1)
        highlighted += int(is_band.any())
        if not is_band.any():
            np.testing.assert_allclose(col[up], np.broadcast_to(base, col[up].shape), atol=1e-6)
    if cls in PAINTED_CLASSES:
        # the body's glossy tops carry the band; glass, cargo and roof units do not
        assert highlighted == sum(tuple(rgb) == BODY for _, rgb in vehicle_parts(v)) >= 1
    else:
        assert highlighted == 0


def test_sun_light_leaves_the_highlight_to_the_material():
    v = _user("van")
    for part, (_, rgb) in zip(_road_user_parts(v, flat=False), vehicle_parts(v)):
        # colours go in linear (pyrender writes c^(1/2.2)), one colour per box: no painted band
        np.testing.assert_allclose(part["colours"][:, :3], np.broadcast_to((np.asarray(rgb) / 255.0) ** 2.2,
                                                                           part["colours"][:, :3].shape), atol=1e-6)
