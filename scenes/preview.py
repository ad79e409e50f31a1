"""The contact sheet of a sequence (``preview.png``): for people, not for scoring.

Top row: frames with every vehicle's ground-truth track drawn (past in its
colour, the current bbox as a box). A trail is drawn where the ground it was on
is in the shown frame (each past position moved by the ground-truth global shift
of the pairs since), so it follows the road rather than the camera's drift; it is
broken where the vehicle was not visible. Bottom row: the ground-truth flow of
the pair starting at that frame in Middlebury colours (invalid pixels black), one
shared scale, with the colour-wheel legend at the end. Labels sit on a band of
their own, above the pictures' pixels.
"""

from __future__ import annotations

import cv2
import numpy as np

from algorithms.flow import color_wheel_image, flow_to_color

__all__ = ["PreviewCollector"]

N_COLUMNS = 4
THUMB_WIDTH_PX = 320


def _label(img: np.ndarray, text: str, *, scale: float, colour: tuple[int, int, int],
           band: tuple[int, int, int]) -> None:
    """``text`` at the top left of ``img`` (in place), on a filled band so no pixel under it hides it."""
    (w, h), baseline = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    cv2.rectangle(img, (0, 0), (w + 6, h + baseline + 3), band, thickness=cv2.FILLED)
    cv2.putText(img, text, (3, h + 2), cv2.FONT_HERSHEY_SIMPLEX, scale, colour, 1, cv2.LINE_AA)


def _trail_runs(rows: list[dict], frame: int, ground_px: np.ndarray | None) -> list[np.ndarray]:
    """A vehicle's visible positions up to ``frame``, moved to where their ground is in ``frame``
    (``ground_px[k]``: where frame 0's ground has moved by frame k; None: left as they are), split
    where frames are missing: each run (M, 2) float64 px."""
    runs: list[list] = []
    last = None
    for r in rows:
        k = int(r["frame"])
        if last is None or k != last + 1:
            runs.append([])
        offset = (ground_px[frame] - ground_px[k]) if ground_px is not None else 0.0
        runs[-1].append(np.array([r["x_px"], r["y_px"]], np.float64) + offset)
        last = k
    return [np.array(run) for run in runs]


def _track_colour(vehicle_id: int) -> tuple[int, int, int]:
    hue = (vehicle_id * 47) % 180
    hsv = np.uint8([[[hue, 220, 255]]])
    return tuple(int(c) for c in cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)[0, 0])


class PreviewCollector:
    """Keeps the few frames and flows the sheet shows while a sequence streams past."""

    def __init__(self, n_frames: int):
        k = min(N_COLUMNS, n_frames - 1)
        self.pick = sorted({int(round(j)) for j in np.linspace(0, n_frames - 2, k)})
        self.frames: dict[int, np.ndarray] = {}
        self.flows: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def add(self, fo) -> None:
        if fo.index in self.pick:
            self.frames[fo.index] = fo.rgb
        if fo.pair is not None and fo.pair_index in self.pick:
            self.flows[fo.pair_index] = (fo.pair.flow, fo.pair.valid)

    def sheet(self, tracks: list[dict], *, global_shift_px: np.ndarray | None = None) -> np.ndarray | None:
        """The contact sheet, (h, w, 3) uint8 RGB, or None before any frame.

        ``global_shift_px`` (n_frames, 2) float px: the ground-truth global shift of pair k -> k+1 in
        row k (NaN where there is none); with it, trails are drawn where their ground is in the shown
        frame, without it in the image coordinates of their own frames.
        """
        if not self.frames:
            return None
        ground_px = None
        if global_shift_px is not None:
            shift = np.nan_to_num(np.asarray(global_shift_px, np.float64).reshape(-1, 2))
            ground_px = np.vstack([np.zeros((1, 2)), np.cumsum(shift, axis=0)])
        h, w = next(iter(self.frames.values())).shape[:2]
        scale = min(1.0, THUMB_WIDTH_PX / w)
        tw, th = int(round(w * scale)), int(round(h * scale))
        max_mag = max([float(np.nanmax(np.hypot(f[..., 0], f[..., 1])[v])) if v.any() else 0.0
                       for f, v in self.flows.values()] + [1e-6])
        # the source row and column of each thumbnail pixel under cv2's INTER_NEAREST
        src_x = cv2.resize(np.arange(w, dtype=np.float32)[None, :], (tw, 1), interpolation=cv2.INTER_NEAREST)
        src_y = cv2.resize(np.arange(h, dtype=np.float32)[:, None], (1, th), interpolation=cv2.INTER_NEAREST)
        src_x, src_y = src_x.ravel().astype(np.intp), src_y.ravel().astype(np.intp)
        top, bottom = [], []
        for i in self.pick:
            img = self.frames[i].copy()
            by_vehicle: dict[int, list] = {}
            for r in sorted(tracks, key=lambda r: r["frame"]):
                if r["frame"] <= i and r["visible"]:
                    by_vehicle.setdefault(r["vehicle_id"], []).append(r)
            for vid, rows in by_vehicle.items():
                col = _track_colour(vid)
                runs = [np.round(run).astype(np.int32).reshape(-1, 1, 2) for run in _trail_runs(rows, i, ground_px)]
                cv2.polylines(img, runs, False, col, 1, cv2.LINE_AA)
                last = rows[-1]
                if last["frame"] == i and np.isfinite(last["bbox_x0_px"]):
                    cv2.rectangle(img, (int(last["bbox_x0_px"]), int(last["bbox_y0_px"])),
                                  (int(np.ceil(last["bbox_x1_px"])), int(np.ceil(last["bbox_y1_px"]))), col, 1)
            top.append(cv2.resize(img, (tw, th), interpolation=cv2.INTER_AREA))
            _label(top[-1], f"frame {i}", scale=0.4, colour=(255, 255, 255), band=(0, 0, 0))
            f, v = self.flows[i]
            # colour only the pixels the thumbnail keeps (flow_to_color is per pixel given max_mag): the
            # colours of the nearest-neighbour thumbnail of the full colour image, at a fraction of its cost
            fc = flow_to_color(f[np.ix_(src_y, src_x)], max_magnitude=max_mag, valid=v[np.ix_(src_y, src_x)])
            _label(fc, f"flow {i}->{i + 1}", scale=0.35, colour=(0, 0, 0), band=(255, 255, 255))
            bottom.append(fc)
        legend = np.full((th, th, 3), 255, np.uint8)
        size = max(3, th - 24)
        legend[4:4 + size, (th - size) // 2:(th - size) // 2 + size] = color_wheel_image(size)
        cv2.putText(legend, f"{max_mag:.1f} px", (4, th - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1)
        blank = np.full((th, th, 3), 255, np.uint8)
        return np.vstack([np.hstack(top + [blank]), np.hstack(bottom + [legend])])
