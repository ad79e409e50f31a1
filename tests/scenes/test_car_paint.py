"""Vehicles' look: body colours by their road shares, glass, a highlight that leaves the boxes exact."""

from __future__ import annotations

import numpy as np

from scenes.car_paint import CAR_COLOURS, HIGHLIGHT, car_colour, vehicle_parts
from scenes.world import vehicle_boxes


def test_body_colours_follow_their_shares_on_the_road():
    rng = np.random.default_rng(0)
    bases = np.array([c for _, c in CAR_COLOURS], float)
    drawn = np.array([car_colour(rng) for _ in range(4000)], float)
    family = np.argmin(((drawn[:, None, :] - bases[None]) ** 2).sum(axis=2), axis=1)
    share = np.bincount(family, minlength=len(bases)) / len(drawn)
    expected = np.array([s for s, _ in CAR_COLOURS])
    np.testing.assert_allclose(share, expected, atol=0.02)
    assert share[:4].sum() > 0.7  # white, black, grey, silver: three cars in four
    # and cars of one family differ a little (no two identical whites in a row of parked cars)
    whites = drawn[family == 0]
    assert np.ptp(whites[:, 0]) > 20


def test_the_highlight_is_painted_on_the_tops_and_leaves_every_box_exact():
    boxes = vehicle_boxes(4.5, 1.9, 1.5)
    body, glass = (150, 36, 34), (34, 40, 48)
    parts = vehicle_parts(boxes, (body, glass, body), glossy=(True, False, True), side_shade=0.72,
                          paint_highlight=True)
    for box, part, gloss in zip(boxes, parts, (True, False, True)):
        c, h = np.asarray(box.centre), np.asarray(box.size) / 2
        pos = part["positions"]
        np.testing.assert_allclose(pos.min(axis=0), c - h, atol=1e-6)
        np.testing.assert_allclose(pos.max(axis=0), c + h, atol=1e-6)
        top = part["normals"][:, 2] > 0.5
        np.testing.assert_allclose(pos[top, 2], c[2] + h[2], atol=1e-6)
        # the top's strips tile the whole top face: their areas add up to length x width
        tri = pos[part["indices"].astype(int)]
        up = part["normals"][part["indices"][:, 0].astype(int), 2] > 0.5
        e1, e2 = tri[up, 1, :2] - tri[up, 0, :2], tri[up, 2, :2] - tri[up, 0, :2]
        area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
        np.testing.assert_allclose(area, 4 * h[0] * h[1], rtol=1e-5)
        # every triangle's normal points out of the box (walls seen from outside)
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        centre_to_face = tri.mean(axis=1) - c
        assert (np.einsum("ij,ij->i", n, centre_to_face) > 0).all()
        cols = part["colours"][top, :3] * 255
        rgb = np.asarray(body if gloss else glass, float)
        levels = np.unique(np.round(cols, 3), axis=0)
        if gloss:
            assert len(levels) == 2
            np.testing.assert_allclose(levels.max(axis=0), rgb + HIGHLIGHT * (255 - rgb), atol=0.01)
        else:
            assert len(levels) == 1
        walls = np.abs(part["normals"][:, 2]) < 0.5
        np.testing.assert_allclose(part["colours"][walls, :3] * 255, np.tile(0.72 * rgb, (walls.sum(), 1)), atol=0.01)
    # under sun light the material's gloss makes the highlight: nothing painted
    plain = vehicle_parts(boxes, (body, glass, body), glossy=(True, False, True), side_shade=1.0,
                          paint_highlight=False)
    assert len(np.unique(np.round(plain[0]["colours"], 4), axis=0)) == 1
