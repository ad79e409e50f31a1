"""Size relative to the sequence's vehicles (algorithms.sequence_size) and its pipeline keys."""

import math

import cv2
import numpy as np
import pytest

from algorithms.detection import Detection
from algorithms.pipeline import Pipeline, PipelineError, get_pipeline
from algorithms.sequence_size import (SEQUENCE_SIZE_DEFAULTS, check_sequence_size, equivalent_gsd,
                                      relative_size_keep, typical_mover)


def _det(x0, y0, x1, y1, u, v):
    return Detection((x0 + x1) / 2, (y0 + y1) / 2, (x1 - x0 + 1) * (y1 - y0 + 1), float(x0), float(y0), float(x1),
                     float(y1), float(u), float(v))


def test_the_typical_mover_is_the_vehicles_where_slow_pedestrians_outnumber_them():
    # KIT AIS's MOS155-179 in miniature: 5 cars (30 x 20 px, 15 px a frame) and 10 pedestrians (8 x 8 px, 3 px a
    # frame) a frame, and a roof's parallax (200 x 100 px, 1 px a frame)
    rng = np.random.default_rng(3)
    areas = np.r_[rng.normal(600, 40, 50), rng.normal(64, 6, 100), [20000.0] * 4]
    speeds = np.r_[rng.normal(15, 2, 50), rng.normal(3, 0.5, 100), [1.0] * 4]
    area, speed = typical_mover(areas, speeds)
    assert np.median(areas) < 100  # the plain median is a pedestrian's
    assert 500 < area < 700 and 12 < speed < 18
    # unknown speeds and empty boxes are left out; nothing known, nothing typical
    a2, s2 = typical_mover(np.r_[areas, [0.0, 5.0]], np.r_[speeds, [20.0, np.nan]])
    assert (a2, s2) == (area, speed)
    assert all(math.isnan(x) for x in typical_mover([100.0, 200.0], [0.0, np.nan]))
    with pytest.raises(ValueError, match=r"speeds_px: expected 2 values \(one per area\), got 1"):
        typical_mover([1.0, 2.0], [1.0])


def test_small_slow_and_huge_detections_are_left_out_and_parts_of_fast_vehicles_kept():
    car = _det(100, 50, 129, 69, 15.0, 0.0)  # 600 px, the typical mover
    pedestrian = _det(10, 10, 17, 17, 2.0, 2.0)  # 64 px at 2.8 px a frame
    car_part = _det(200, 50, 209, 57, 14.0, 0.0)  # 80 px: a box short of a fast car
    bus = _det(300, 50, 389, 79, 12.0, 0.0)  # 2730 px: 4.6 cars
    roof = _det(400, 0, 599, 99, 1.0, 0.0)  # 20000 px
    unknown = _det(20, 30, 27, 37, math.nan, math.nan)  # 64 px, speed unknown: never judged slow
    dets = [car, pedestrian, car_part, bus, roof, unknown]
    keep = relative_size_keep(dets, 600.0, 15.0, small_rel=0.25, slow_rel=0.5, large_rel=12.0)
    assert keep == [True, False, True, True, False, True]
    # each half alone, and both off (the defaults)
    assert relative_size_keep(dets, 600.0, 15.0, small_rel=0.25, large_rel=0.0) == [True, False, True, True, True,
                                                                                      True]
    assert relative_size_keep(dets, 600.0, 15.0, small_rel=0.0, large_rel=12.0) == [True, True, True, True, False,
                                                                                      True]
    assert relative_size_keep(dets, 600.0, 15.0) == [True] * 6
    # no typical mover yet: nothing judged
    assert relative_size_keep(dets, math.nan, math.nan, small_rel=0.25, large_rel=12.0) == [True] * 6


H, W = 160, 240


def _layer(rng, length, width, *, outline=25.0, roof=150.0):
    """A mover seen from above at (0, 0) of an (H, W) layer: dark outline, a roof with a few light patches."""
    img, alpha = np.zeros((H, W), np.float32), np.zeros((H, W), np.float32)
    img[:width, :length], alpha[:width, :length] = outline, 1.0
    img[2:width - 2, 2:length - 2] = roof
    for _ in range(4):
        x, y = int(rng.integers(2, max(3, length - 4))), int(rng.integers(2, max(3, width - 3)))
        img[y:y + 2, x:x + 2] = 235.0
    return img, alpha


def _street(n, seed=0):
    """``n`` uint8 frames of a still camera: three cars (26 x 14 px) at 4 px a frame, a pedestrian (8 x 8 px) at 1.5."""
    rng = np.random.default_rng(seed)
    ground = cv2.GaussianBlur(rng.uniform(40, 220, (H, W)).astype(np.float32), (0, 0), 1.2)
    movers = [(_layer(rng, 26, 14), (20, 20), 4.0), (_layer(rng, 26, 14), (120, 50), -4.0),
              (_layer(rng, 26, 14), (30, 80), 4.0), (_layer(rng, 8, 8, outline=20.0, roof=230.0), (100, 125), 1.5)]
    frames = []
    for t in range(n):
        f = ground.copy()
        for (img, alpha), (x, y), u in movers:
            M = np.float32([[1, 0, x + u * t], [0, 1, y]])
            a = cv2.warpAffine(alpha, M, (W, H))
            f = f * (1 - a) + cv2.warpAffine(img, M, (W, H))
        frames.append(np.clip(f, 0, 255).astype(np.uint8))
    return frames


def test_the_pipeline_leaves_out_the_pedestrian_once_the_history_knows_the_cars():
    frames = _street(12)
    on = [e.detections for e in _pipeline(small_rel=0.25, min_history=6, history=100).run(frames)
          if hasattr(e, "detections")]
    off = [e.detections for e in _pipeline().run(frames) if hasattr(e, "detections")]

    def walker(ds):  # the pedestrian's row, y 125..132
        return [d for d in ds if 120 <= d.y_px <= 136]

    assert all(len(walker(ds)) == 1 and len(ds) == 4 for ds in off)  # the detector finds all four movers
    assert len(walker(on[0])) == 1  # 4 detections in the history: nothing judged yet
    assert all(walker(ds) == [] and len(ds) == 3 for ds in on[1:])  # then the cars stay, the pedestrian goes


@pytest.mark.parametrize("name", ["dis", "pyramidal-hs"])
def test_the_built_in_pipelines_leave_out_the_pedestrian_without_a_ground_sampling_distance(name):
    # on in dis and pyramidal-hs (small_rel 0.25): the 20 detections of pairs 0-4 are the history, from pair 4 on
    # the pedestrian (0.18 times a car's box, 1.5 px a frame against 4) is left out, the cars stay
    out = [e.detections for e in get_pipeline(name).run(_street(12)) if hasattr(e, "detections")]
    walkers = [len([d for d in ds if 120 <= d.y_px <= 136]) for ds in out]
    assert walkers[:4] == [1, 1, 1, 1] and walkers[4:] == [0] * (len(out) - 4), walkers
    assert all(len(ds) == 3 for ds in out[4:])


def _pipeline(**section):
    return Pipeline.from_dict({
        "name": "sizes", "global_motion": {"method": "ncc_global_motion", "params": {"max_shift": 4}},
        "jitter": None, "compensation": "shift", "flow": {"method": "dis"}, "threshold": None,
        "spatial": False, "temporal": False,
        "detection": {"sequence_size": section} if section else {},
        "tracking": {"point": False, "multi": None}})


@pytest.mark.parametrize("section, match", [
    ({"small_rel": -0.1}, r"detection.sequence_size.small_rel: expected a finite number >= 0"),
    ({"large_rel": 0.5}, r"detection.sequence_size.large_rel: expected 0 \(off\) or a number > 1, got 0.5"),
    ({"min_history": 0}, r"detection.sequence_size.min_history: expected an integer >= 1, got 0"),
    ({"history": 2.5}, r"detection.sequence_size.history: expected an integer"),
    ({"history": 10}, r"detection.sequence_size.history: expected at least min_history \(20\), got 10"),
    ({"bogus": 1}, r"detection.sequence_size.bogus: unknown key; valid: small_rel"),
    ({"vehicle_m2": 0}, r"detection.sequence_size.vehicle_m2: expected null or a finite number > 0, got 0"),
    ({"vehicle_m2": True}, r"detection.sequence_size.vehicle_m2: expected null or a finite number > 0, got True"),
])
def test_bad_sequence_size_keys_are_rejected_naming_them(section, match):
    with pytest.raises(PipelineError, match=match):
        _pipeline(**section)


def test_the_defaults_are_the_pipeline_keys_and_off():
    assert _pipeline().config["detection"]["sequence_size"] == SEQUENCE_SIZE_DEFAULTS
    assert check_sequence_size({}) == SEQUENCE_SIZE_DEFAULTS
    assert SEQUENCE_SIZE_DEFAULTS["small_rel"] == 0 and SEQUENCE_SIZE_DEFAULTS["large_rel"] == 0
    assert SEQUENCE_SIZE_DEFAULTS["vehicle_m2"] is None
    with pytest.raises(ValueError, match=r"sequence_size: unknown key\(s\) \['bogus'\]"):
        check_sequence_size({"bogus": 1})


# -- the m^2 limits without a ground sampling distance (vehicle_m2) ------------------------------------------

def test_the_equivalent_gsd_makes_the_typical_mover_vehicle_m2():
    g = equivalent_gsd(500.0, 20.0)
    assert g == pytest.approx(0.2) and 500.0 * g * g == pytest.approx(20.0)
    # a box a fifth of the typical mover's is 4 m^2 at it: min_box_m2 relative to the clip's vehicles
    assert 100.0 * g * g == pytest.approx(4.0)
    assert equivalent_gsd(math.nan, 20.0) is None and equivalent_gsd(0.0, 20.0) is None
    with pytest.raises(ValueError, match=r"vehicle_m2: expected a finite number > 0, got 0"):
        equivalent_gsd(500.0, 0)


def _walkers(run):
    return [[d for d in e.detections if 120 <= d.y_px <= 136] for e in run if hasattr(e, "detections")]


def test_without_a_gsd_vehicle_m2_drops_what_the_m2_limits_drop_with_it():
    # the street's cars box about 30 x 14 px, the pedestrian 8 x 8 px (1.5 px a frame). At 0.22 m a pixel (the
    # synthetic path: the sequence's ground sampling distance) the cars are about 20 m^2 and the pedestrian's
    # region and box are under min_area_m2 (3) and min_box_m2 (4): dropped on every pair. Without it and with
    # vehicle_m2 20, the same limits apply relative to the cars once the history holds min_history detections.
    frames = _street(12)
    with_gsd = _walkers(_pipeline(min_history=6, history=100).run(frames, gsd_m_per_px=0.22))
    without = _walkers(_pipeline(min_history=6, history=100).run(frames))
    relative = _pipeline(vehicle_m2=20.0, min_history=6, history=100)
    out = [e.detections for e in relative.run(frames) if hasattr(e, "detections")]
    assert all(w == [] for w in with_gsd) and all(len(w) == 1 for w in without)
    walk = [[d for d in ds if 120 <= d.y_px <= 136] for ds in out]
    assert len(walk[0]) == 1 and len(walk[1]) == 1  # 4 detections a pair: the history is not full before pair 2
    assert all(w == [] for w in walk[2:]), walk
    assert all(len(ds) == 3 for ds in out[2:])  # the cars stay
    # the m^2 areas it fills are those of the equivalent ground sampling distance: the cars about vehicle_m2
    cars = [d.area_m2 * (d.x1_px - d.x0_px + 1) * (d.y1_px - d.y0_px + 1) / d.area_px for d in out[-1]]
    assert all(10.0 < a < 40.0 for a in cars), cars


def test_vehicle_m2_leaves_a_known_ground_sampling_distance_alone():
    # at 0.5 m a pixel the pedestrian's box is 16 m^2, within the limits: kept, though vehicle_m2 would drop it
    frames = _street(8)
    a = [e.detections for e in _pipeline(min_history=6, history=100).run(frames, gsd_m_per_px=0.5)
         if hasattr(e, "detections")]
    b = [e.detections for e in _pipeline(vehicle_m2=20.0, min_history=6, history=100).run(frames, gsd_m_per_px=0.5)
         if hasattr(e, "detections")]
    assert a == b and all(len(ds) == 4 for ds in a)
