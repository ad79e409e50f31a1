"""The contact sheet (preview.png): labels stay legible over invalid pixels, and track trails follow the
ground (drawn in the shown frame's coordinates, broken where the vehicle was not seen)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from scenes.preview import PreviewCollector, _track_colour

H, W = 120, 160
N = 13          # the sheet shows frames 0, 4, 7, 11
CAMERA_PX = (3.0, 0.0)   # the ground moves 3 px right per frame in the image (camera drift)
OWN_PX = (0.0, 2.0)      # the vehicle drives 2 px down per frame on the ground
START = (20.0, 30.0)


def _collector(*, valid_fraction: float = 1.0, hidden: tuple[int, ...] = ()) -> tuple[np.ndarray, list[int]]:
    rng = np.random.default_rng(7)
    pc = PreviewCollector(N)
    for i in range(N):
        flow = np.full((H, W, 2), (2.0, 1.0), np.float32)
        valid = rng.random((H, W)) < valid_fraction
        pair = SimpleNamespace(flow=flow, valid=valid) if i < N - 1 else None
        pc.add(SimpleNamespace(index=i, rgb=np.zeros((H, W, 3), np.uint8), pair=pair, pair_index=i))
    tracks = []
    for k in range(N):
        x = START[0] + k * (CAMERA_PX[0] + OWN_PX[0])
        y = START[1] + k * (CAMERA_PX[1] + OWN_PX[1])
        tracks.append({"frame": k, "vehicle_id": 1, "x_px": x, "y_px": y, "bbox_x0_px": np.nan,
                       "bbox_y0_px": np.nan, "bbox_x1_px": np.nan, "bbox_y1_px": np.nan, "visible": k not in hidden})
    shift = np.tile(np.array(CAMERA_PX), (N, 1))
    shift[-1] = np.nan  # no pair after the last frame
    return pc.sheet(tracks, global_shift_px=shift), pc.pick


def _trail_pixels(sheet: np.ndarray, column: int) -> np.ndarray:
    """(row, col) of the pixels of the frame panel ``column`` drawn in the vehicle's colour (or close)."""
    panel = sheet[:H, column * W:(column + 1) * W].astype(int)
    colour = np.array(_track_colour(1))
    near = np.abs(panel - colour).sum(-1) < 120
    near[:20] = False  # the "frame N" label
    return np.argwhere(near)


def test_trails_follow_the_ground_not_the_image():
    sheet, pick = _collector()
    assert pick == [0, 4, 7, 11]
    i = pick[-1]
    pts = _trail_pixels(sheet, 3)
    assert len(pts) > 10
    # in frame i, where the ground of each earlier frame is now: a line along the vehicle's own motion
    # (straight down at x = START + i * camera shift), not the diagonal of its image positions
    x_now = START[0] + i * CAMERA_PX[0]
    assert np.abs(pts[:, 1] - x_now).max() <= 1.5, sorted(set(pts[:, 1]))
    assert pts[:, 0].min() <= START[1] + 1 and pts[:, 0].max() >= START[1] + i * OWN_PX[1] - 1


def test_a_trail_is_broken_where_the_vehicle_was_not_seen():
    sheet, pick = _collector(hidden=(4, 5, 6, 7))
    pts = _trail_pixels(sheet, 3)
    rows = set(pts[:, 0].tolist())
    y = lambda k: START[1] + k * OWN_PX[1]  # noqa: E731
    assert any(abs(r - y(1)) <= 1 for r in rows) and any(abs(r - y(10)) <= 1 for r in rows)
    gap = [r for r in rows if y(3) + 1.5 < r < y(8) - 1.5]
    assert not gap, f"the trail is drawn across the frames the vehicle was not seen: rows {sorted(gap)}"


def test_flow_labels_sit_on_a_band_above_the_invalid_pixels():
    sheet, pick = _collector(valid_fraction=0.5)
    for column in range(len(pick)):
        label = sheet[H:H + 12, column * W:column * W + 40].astype(int)
        white = (label >= 235).all(-1).mean()
        dark = (label <= 80).all(-1).mean()
        assert white > 0.6, f"column {column}: {white:.0%} of the label's band is white"
        assert 0.02 < dark < 0.35, f"column {column}: {dark:.0%} dark (the label's text, no invalid dots)"
