"""Scene specs: validated descriptions of an aerial sequence, from YAML files or presets.

A :class:`SceneSpec` says everything the generator needs (image, camera and its
drift and jitter, world, vehicles, lighting, the sensor, seed); nothing else
influences the frames. Models forbid unknown keys and refuse NaN and infinity; errors are
:class:`SceneSpecError` (a ``ValueError``) naming the source (file or preset)
and the dotted field.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

__all__ = [
    "GENERATOR_VERSION",
    "SceneSpecError",
    "ImageSpec",
    "IntrinsicsSpec",
    "DriftSpec",
    "JitterSpec",
    "CameraSpec",
    "BuildingsSpec",
    "TreesSpec",
    "WorldSpec",
    "VehiclesSpec",
    "ClassMixSpec",
    "TrafficSpec",
    "LightSpec",
    "MotionBlurSpec",
    "RollingShutterSpec",
    "LensSpec",
    "HazeSpec",
    "NoiseSpec",
    "CompressionSpec",
    "SensorSpec",
    "MOVED_KEYS",
    "SceneSpec",
    "PRESET_DIR",
    "list_presets",
    "load_scene_spec",
    "spec_hash",
    "spec_to_yaml",
]

# Bump when the same spec would render different frames or truth.
GENERATOR_VERSION = "2.7.0"  # 2.7.0: tracks.csv boxes clipped to the image, visible_fraction on the image under a lens

PRESET_DIR = Path(__file__).resolve().parent / "presets"

# A vehicle may move at most this fraction of the image's smaller side per frame
# relative to the ground; beyond it no flow method (and no viewer) can follow it.
MAX_VEHICLE_STEP_FRACTION = 0.1
# The camera may move the ground at most this fraction of the image per frame.
MAX_CAMERA_STEP_FRACTION = 0.25
# The top image edge of an oblique camera must stay this far below the horizon.
MAX_RAY_OFF_NADIR_DEG = 75.0


class SceneSpecError(ValueError):
    """A scene spec is invalid; the message names the source and the field."""


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, validate_assignment=False)


class ImageSpec(_Model):
    width_px: int = Field(640, ge=16, le=4096, description="image width")
    height_px: int = Field(480, ge=16, le=4096, description="image height")
    n_frames: int = Field(60, ge=2, le=100_000, description="number of frames (>= 2: a pair)")
    fps: float = Field(10.0, gt=0, le=1000, description="frame rate, frames per second")


class IntrinsicsSpec(_Model):
    """Pinhole intrinsics; give ``focal_length_px`` or ``hfov_deg`` (horizontal field of view)."""

    focal_length_px: float | None = Field(None, gt=0)
    hfov_deg: float | None = Field(None, gt=1, lt=150)

    @model_validator(mode="after")
    def _one_of(self) -> "IntrinsicsSpec":
        if self.focal_length_px is not None and self.hfov_deg is not None:
            raise ValueError("give focal_length_px or hfov_deg, not both")
        return self

    def focal_px(self, width_px: int) -> float:
        if self.focal_length_px is not None:
            return float(self.focal_length_px)
        hfov = 60.0 if self.hfov_deg is None else self.hfov_deg
        return (width_px / 2.0) / math.tan(math.radians(hfov) / 2.0)


class DriftSpec(_Model):
    """Slow, smooth departures from a straight level flight line."""

    heading_rate_deg_s: float = Field(0.0, ge=-30, le=30, description="slow turn of the flight line")
    crab_deg: float = Field(0.0, ge=-90, le=90,
                            description="camera yaw relative to the track (crosswind crab, or a camera mounted sideways)")
    climb_rate_mps: float = Field(0.0, ge=-50, le=50, description="altitude change per second")


class JitterSpec(_Model):
    """Wind and turbulence (thesis 3.2): Ornstein-Uhlenbeck perturbations of the camera pose."""

    roll_std_deg: float = Field(0.0, ge=0, le=10)
    pitch_std_deg: float = Field(0.0, ge=0, le=10)
    yaw_std_deg: float = Field(0.0, ge=0, le=10)
    x_std_m: float = Field(0.0, ge=0, le=100)
    y_std_m: float = Field(0.0, ge=0, le=100)
    z_std_m: float = Field(0.0, ge=0, le=100)
    correlation_time_s: float = Field(0.5, gt=0, le=1000, description="OU correlation time tau")


class CameraSpec(_Model):
    intrinsics: IntrinsicsSpec = Field(default_factory=IntrinsicsSpec)
    altitude_m: float = Field(120.0, gt=5, le=10_000)
    ground_speed_mps: float = Field(12.0, ge=0, le=500)
    heading_deg: float = Field(0.0, ge=-360, le=360, description="direction of flight, clockwise from north (+y)")
    tilt_deg: float = Field(0.0, ge=0, le=60, description="0 = nadir; > 0 looks forward (oblique)")
    drift: DriftSpec = Field(default_factory=DriftSpec)
    jitter: JitterSpec = Field(default_factory=JitterSpec)


class BuildingsSpec(_Model):
    """Flat-roofed buildings with parapets and roof units, on built-up blocks, clear of roads and each other."""

    count: int = Field(0, ge=0, le=2000, description="buildings wanted; fewer when the built-up blocks are full")
    height_range_m: tuple[float, float] = (6.0, 30.0)
    footprint_range_m: tuple[float, float] = (8.0, 25.0)

    @model_validator(mode="after")
    def _ranges(self) -> "BuildingsSpec":
        for name in ("height_range_m", "footprint_range_m"):
            lo, hi = getattr(self, name)
            if not 0 < lo <= hi:
                raise ValueError(f"{name}: expected 0 < low <= high, got ({lo}, {hi})")
        return self


class TreesSpec(_Model):
    """Trees (single, and dense in woods) and hedges: static instanced meshes standing above the ground."""

    density_per_ha: float = Field(6.0, ge=0, le=400, description="single trees per hectare of grass and yards")
    wood_density_per_ha: float = Field(250.0, ge=0, le=1000, description="trees per hectare of wood blocks")
    hedge_fraction: float = Field(0.35, ge=0, le=1, description="share of field and grass block sides with a hedge")
    crown_diameter_range_m: tuple[float, float] = (3.5, 8.0)
    height_range_m: tuple[float, float] = (5.0, 14.0)
    conifer_fraction: float = Field(0.15, ge=0, le=1, description="share of single trees that are conifers")

    @model_validator(mode="after")
    def _ranges(self) -> "TreesSpec":
        for name in ("crown_diameter_range_m", "height_range_m"):
            lo, hi = getattr(self, name)
            if not 0 < lo <= hi:
                raise ValueError(f"{name}: expected 0 < low <= high, got ({lo}, {hi})")
        return self


class WorldSpec(_Model):
    """An irregular road network (a jittered, rotated grid of curved roads with T junctions) and land use."""

    road_spacing_m: float = Field(60.0, ge=20, le=2000, description="mean distance between neighbouring roads")
    road_width_m: float = Field(8.0, ge=3, le=40, description="width of the main roads (minor roads: 3/4 of it)")
    road_irregularity: float = Field(0.6, ge=0, le=1,
                                     description="0 = a straight regular grid; 1 = junctions moved by up to a "
                                                 "quarter spacing and roads bent by up to 15 % of their length")
    road_drop_fraction: float = Field(0.25, ge=0, le=0.6,
                                      description="share of minor road segments left out (T junctions, big blocks)")
    parking_fraction: float = Field(0.1, ge=0, le=1, description="share of blocks that are parking lots")
    built_fraction: float = Field(0.2, ge=0, le=1, description="share of blocks that are built-up yards "
                                                                 "(where buildings stand)")
    wood_fraction: float = Field(0.1, ge=0, le=1, description="share of blocks that are woods")
    crosswalk_fraction: float = Field(0.5, ge=0, le=1, description="share of junctions with zebra crossings "
                                                                    "on every road into them")
    clutter: float = Field(0.0, ge=0, le=4,
                           description="small things on the ground, relative to a central European city (1): "
                                       "manholes, gullies, patched cuts, sealed cracks, oil strips down the "
                                       "lanes, lamp posts, and bins, sheds, planters and garden walls in built "
                                       "blocks, with their shadows (0: none)")
    detail: float = Field(0.0, ge=0, le=3,
                          description="structure at 1-3 m, relative to a central European town (1): "
                                      "lit and shaded patches in the ground's materials (worn and stained "
                                      "paving, tufts, things in yards), light and soil at 2-4 m over the "
                                      "ground, leaf clumps in tree crowns and panels, vents and patches on "
                                      "roofs (0: none)")
    edges: float = Field(0.0, ge=0, le=1,
                         description="sharp edges of high contrast, relative to a central European city (1): "
                                     "light kerbs with a dark gutter, a dashed centre line and parking-lane "
                                     "lines on minor roads (the share of them marked), roofs from white gravel "
                                     "to dark bitumen and red tiles, each with a parapet that stands out "
                                     "(0: none)")
    buildings: BuildingsSpec = Field(default_factory=BuildingsSpec)
    trees: TreesSpec = Field(default_factory=TreesSpec)

    @model_validator(mode="after")
    def _fractions(self) -> "WorldSpec":
        total = self.parking_fraction + self.built_fraction + self.wood_fraction
        if total > 1.0 + 1e-9:
            raise ValueError(f"parking_fraction + built_fraction + wood_fraction: expected <= 1, got {total:g}")
        return self


class VehiclesSpec(_Model):
    count: int = Field(6, ge=0, le=500)
    parked_fraction: float = Field(0.2, ge=0, le=1)
    length_m: float = Field(4.5, gt=0, le=30)
    width_m: float = Field(1.9, gt=0, le=5)
    height_m: float = Field(1.5, gt=0, le=5)
    speed_range_mps: tuple[float, float] = (5.0, 15.0)
    turning_fraction: float = Field(0.2, ge=0, le=1)
    accelerating_fraction: float = Field(0.2, ge=0, le=1)
    stopping_fraction: float = Field(0.1, ge=0, le=1)
    acceleration_mps2: float = Field(2.0, gt=0, le=20)

    @model_validator(mode="after")
    def _ranges(self) -> "VehiclesSpec":
        lo, hi = self.speed_range_mps
        if not 0 <= lo <= hi:
            raise ValueError(f"speed_range_mps: expected 0 <= low <= high, got ({lo}, {hi})")
        total = self.turning_fraction + self.accelerating_fraction + self.stopping_fraction
        if total > 1.0 + 1e-9:
            raise ValueError(
                "turning_fraction + accelerating_fraction + stopping_fraction: expected <= 1, "
                f"got {total:g}")
        return self


class ClassMixSpec(_Model):
    """Shares of the vehicle classes in moving traffic (relative weights; sizes in scenes/traffic.py CLASS_SIZES_M)."""

    car: float = Field(0.82, ge=0, le=1)
    van: float = Field(0.1, ge=0, le=1)
    truck: float = Field(0.03, ge=0, le=1)
    bus: float = Field(0.03, ge=0, le=1)
    motorbike: float = Field(0.02, ge=0, le=1)

    @model_validator(mode="after")
    def _some(self) -> "ClassMixSpec":
        total = self.car + self.van + self.truck + self.bus + self.motorbike
        if total <= 0:
            raise ValueError("car + van + truck + bus + motorbike: expected > 0 (some class must drive), got 0")
        return self


class TrafficSpec(_Model):
    """Simulated city traffic (scenes/traffic.py), beside the ``vehicles:`` placed one by one.

    Moving vehicles follow each other (Intelligent Driver Model, a hard minimum gap), queue at
    traffic lights at junctions, turn and change lanes; parked cars stand along kerbs and in
    parking lots; pedestrians walk on footpaths, cyclists ride in the kerb lane. Street trees
    overhang the roads and footbridges cross them (occluders). Everything defaults to off (0).
    """

    density_per_lane_km: float = Field(0.0, ge=0, le=150,
                                       description="moving (or queued) vehicles per km of lane; 0 = no traffic; "
                                                   "free urban flow 10-25, dense city 30-60, jam 100+")
    classes: ClassMixSpec = Field(default_factory=ClassMixSpec)
    speed_range_mps: tuple[float, float] = Field((8.0, 14.0), description="desired speeds, drawn per vehicle")
    turn_speed_mps: float = Field(6.0, gt=0, le=20, description="speed through a turn at a junction")
    acceleration_mps2: float = Field(1.5, gt=0, le=6, description="IDM maximum acceleration a")
    deceleration_mps2: float = Field(2.5, gt=0, le=9, description="IDM comfortable deceleration b")
    min_gap_m: float = Field(2.0, ge=0.5, le=10, description="IDM jam distance s0 (bumper to bumper, standing)")
    time_headway_s: float = Field(1.2, ge=0.3, le=5, description="IDM safe time headway T")
    junctions: Literal["lights", "none"] = Field("lights", description="traffic lights (two phases: one axis "
                                                                      "green, then the other; left turns give way) "
                                                                      "or uncontrolled")
    green_s: float = Field(15.0, ge=2, le=120, description="green time of each phase")
    clearance_s: float = Field(3.0, ge=0, le=20, description="amber and all-red between two phases")
    turning_fraction: float = Field(0.3, ge=0, le=1, description="share of junction crossings that turn")
    lane_change_fraction: float = Field(0.2, ge=0, le=1, description="share of multi-lane legs with a lane change")
    warmup_s: float = Field(20.0, ge=0, le=300, description="simulated before frame 0 (queues form)")
    kerb_parking_per_km: float = Field(0.0, ge=0, le=160, description="parked vehicles per km of kerb (each side "
                                                                       "of roads wide enough for a parking lane)")
    lot_fill_fraction: float = Field(0.0, ge=0, le=1, description="share of parking-lot stalls taken")
    pedestrians_per_km: float = Field(0.0, ge=0, le=400, description="pedestrians per km of footpath")
    cyclists_per_lane_km: float = Field(0.0, ge=0, le=40, description="cyclists per km of kerb lane")
    street_trees_per_km: float = Field(0.0, ge=0, le=80, description="trees per km of kerb whose crowns "
                                                                      "overhang the road")
    bridges: int = Field(0, ge=0, le=3, description="footbridges across roads in view")

    @model_validator(mode="after")
    def _ranges(self) -> "TrafficSpec":
        lo, hi = self.speed_range_mps
        if not 0 < lo <= hi:
            raise ValueError(f"speed_range_mps: expected 0 < low <= high, got ({lo}, {hi})")
        return self


class LightSpec(_Model):
    """Sun and sky. ``flat`` renders unlit colours (fast; shadows of static things painted on the ground,
    vehicles carry a translucent shadow quad); ``sun`` lights every surface (about 4x slower) with
    shadow maps when ``shadows``."""

    mode: Literal["flat", "sun"] = "flat"
    sun_elevation_deg: float = Field(50.0, ge=10, le=90)
    sun_azimuth_deg: float = Field(135.0, ge=-360, le=360, description="compass direction of the sun, clockwise "
                                                                      "from north (+y)")
    shadows: bool = True
    ambient: float = Field(0.45, ge=0, le=1, description="sky light: the brightness of shadow relative to sunlit "
                                                         "flat ground")
    illumination_drift_per_s: float = Field(0.0, ge=-0.5, le=0.5, description="relative gain change per second")


# -- the sensor: applied to the rendered light in the order of scenes/sensor.py -------------

class MotionBlurSpec(_Model):
    """Motion blur: the mean of ``subframes`` renders spread evenly over the exposure, centred on the frame time."""

    exposure_s: float = Field(0.0, ge=0, le=1, description="shutter open time, seconds; 0 = off (instantaneous)")
    subframes: int = Field(5, ge=3, le=63,
                           description="renders averaged over the exposure; odd, so the middle one is at the "
                                       "frame time (ground truth stays frame time to frame time)")

    @model_validator(mode="after")
    def _odd(self) -> "MotionBlurSpec":
        if self.subframes % 2 == 0:
            raise ValueError(f"subframes: expected an odd number (the middle render is at the frame time), "
                             f"got {self.subframes}")
        return self


class RollingShutterSpec(_Model):
    """Rolling shutter: row y is read ``(y - cy) * line_delay_s`` after the frame time (cy the centre row).

    Rows are rendered in bands of ``band_rows``: every row of a band is exposed at the
    band's centre time, so the timing error is at most ``band_rows / 2 * line_delay_s``;
    the ground truth is exact for the image so rendered (per band pose).
    """

    line_delay_s: float = Field(0.0, ge=0, le=1e-3,
                                description="readout time from one row to the next, seconds; 0 = global shutter")
    band_rows: int = Field(8, ge=1, le=4096,
                           description="rows rendered at one instant: the readout time is quantised to bands "
                                       "(error <= band_rows / 2 * line_delay_s)")


class LensSpec(_Model):
    """Brown-Conrady radial distortion on normalised coordinates, and the optics' blur."""

    k1: float = Field(0.0, ge=-1, le=1, description="radial coefficient of r^2 (< 0 barrel, > 0 pincushion)")
    k2: float = Field(0.0, ge=-1, le=1, description="radial coefficient of r^4")
    blur_sigma_px: float = Field(0.0, ge=0, le=10, description="Gaussian point spread of the optics, px")


class HazeSpec(_Model):
    """Atmospheric contrast loss (Koschmieder): ``I = J t + A (1 - t)``, ``t = exp(-beta distance)``."""

    extinction_per_km: float = Field(0.0, ge=0, le=100, description="beta, per km of line of sight; 0 = off")
    airlight: float = Field(200.0, ge=0, le=255, description="A, the gray level of the haze itself")


class NoiseSpec(_Model):
    """Sensor noise: Poisson shot noise on the photo-electrons, then Gaussian read noise."""

    gaussian_std: float = Field(0.0, ge=0, le=50, description="read noise, gray levels")
    full_well_e: float = Field(0.0, ge=0, le=1e6,
                               description="photo-electrons at gray level 255 for shot noise (fewer = noisier); "
                                           "0 = no shot noise")


class CompressionSpec(_Model):
    """Lossy coding of the frames through a real encoder (JPEG by OpenCV, H.264 by libx264 through PyAV)."""

    codec: Literal["none", "jpeg", "h264"] = "none"
    jpeg_quality: int = Field(75, ge=1, le=100, description="JPEG quality (100 best)")
    h264_crf: int = Field(23, ge=0, le=51, description="x264 constant rate factor (0 lossless, 51 worst)")
    h264_gop: int = Field(30, ge=1, le=1000, description="frames between H.264 key frames")


class SensorSpec(_Model):
    """What the camera does to the rendered light; the order is fixed (README, scenes/sensor.py)."""

    motion_blur: MotionBlurSpec = Field(default_factory=MotionBlurSpec)
    rolling_shutter: RollingShutterSpec = Field(default_factory=RollingShutterSpec)
    lens: LensSpec = Field(default_factory=LensSpec)
    haze: HazeSpec = Field(default_factory=HazeSpec)
    noise: NoiseSpec = Field(default_factory=NoiseSpec)
    compression: CompressionSpec = Field(default_factory=CompressionSpec)


# keys that moved to another section: old dotted key -> new dotted key
MOVED_KEYS = {
    "photometry.noise_std": "sensor.noise.gaussian_std",
    "photometry.blur_sigma_px": "sensor.lens.blur_sigma_px",
    "photometry.lighting": "light.mode",
    "photometry.sun_elevation_deg": "light.sun_elevation_deg",
    "photometry.sun_azimuth_deg": "light.sun_azimuth_deg",
    "photometry.shadows": "light.shadows",
    "photometry.brightness_drift_per_s": "light.illumination_drift_per_s",
}


class SceneSpec(_Model):
    name: str = "custom"
    description: str = ""
    seed: int = Field(0, ge=0, le=2**63 - 1)
    image: ImageSpec = Field(default_factory=ImageSpec)
    camera: CameraSpec = Field(default_factory=CameraSpec)
    world: WorldSpec = Field(default_factory=WorldSpec)
    vehicles: VehiclesSpec = Field(default_factory=VehiclesSpec)
    traffic: TrafficSpec = Field(default_factory=TrafficSpec)
    light: LightSpec = Field(default_factory=LightSpec)
    sensor: SensorSpec = Field(default_factory=SensorSpec)

    @model_validator(mode="before")
    @classmethod
    def _moved_keys(cls, data: Any) -> Any:
        """An old key names its new home instead of a bare 'unknown key'."""
        if not isinstance(data, dict) or "photometry" not in data:
            return data
        old = data["photometry"]
        moved = [f"{k} -> {MOVED_KEYS[k]}" for k in (f"photometry.{name}" for name in old)
                 if k in MOVED_KEYS] if isinstance(old, dict) else []
        raise ValueError("photometry: this section was split into sensor: (noise, blur) and light: (lighting, "
                         f"sun, shadows, drift): {', '.join(moved) if moved else 'see ' + ', '.join(MOVED_KEYS.values())}")

    # -- derived quantities used by the generator and the checks ------------------------
    def focal_px(self) -> float:
        return self.camera.intrinsics.focal_px(self.image.width_px)

    def gsd_m(self) -> float:
        """Ground sampling distance at nadir, metres per pixel, at the lowest altitude flown."""
        duration_s = (self.image.n_frames - 1) / self.image.fps
        lowest_m = self.camera.altitude_m + min(0.0, self.camera.drift.climb_rate_mps * duration_s)
        return lowest_m / self.focal_px()

    @model_validator(mode="after")
    def _physically_possible(self) -> "SceneSpec":
        img, cam = self.image, self.camera
        f_px = self.focal_px()
        duration_s = (img.n_frames - 1) / img.fps
        lowest_m = cam.altitude_m + cam.drift.climb_rate_mps * duration_s
        if lowest_m < 5.0:
            raise ValueError(
                f"camera.drift.climb_rate_mps: the camera would descend to {lowest_m:.1f} m "
                f"(altitude_m {cam.altitude_m} + {cam.drift.climb_rate_mps} m/s x {duration_s:.1f} s); "
                "expected it to stay above 5 m")
        half_vfov_deg = math.degrees(math.atan((img.height_px / 2.0) / f_px))
        if cam.tilt_deg + half_vfov_deg > MAX_RAY_OFF_NADIR_DEG:
            raise ValueError(
                f"camera.tilt_deg: tilt {cam.tilt_deg} + half vertical field of view {half_vfov_deg:.1f} "
                f"= {cam.tilt_deg + half_vfov_deg:.1f} deg off nadir; expected <= {MAX_RAY_OFF_NADIR_DEG} "
                "(the horizon would enter the image)")
        gsd = self.gsd_m()
        side_px = min(img.width_px, img.height_px)
        cam_step_px = cam.ground_speed_mps / img.fps / gsd
        if cam_step_px > MAX_CAMERA_STEP_FRACTION * side_px:
            raise ValueError(
                f"camera.ground_speed_mps: {cam.ground_speed_mps} m/s moves the ground {cam_step_px:.1f} px "
                f"per frame; expected <= {MAX_CAMERA_STEP_FRACTION * side_px:.1f} px "
                f"({MAX_CAMERA_STEP_FRACTION:g} of the image's smaller side)")
        sensor = self.sensor
        frame_s = 1.0 / img.fps
        if sensor.motion_blur.exposure_s > frame_s:
            raise ValueError(
                f"sensor.motion_blur.exposure_s: {sensor.motion_blur.exposure_s:g} s is longer than the frame "
                f"interval {frame_s:g} s at {img.fps:g} fps; expected <= {frame_s:g}")
        readout_s = sensor.rolling_shutter.line_delay_s * (img.height_px - 1)
        if readout_s > frame_s:
            raise ValueError(
                f"sensor.rolling_shutter.line_delay_s: reading {img.height_px} rows takes {readout_s:g} s, longer "
                f"than the frame interval {frame_s:g} s; expected line_delay_s <= {frame_s / (img.height_px - 1):g}")
        lens = sensor.lens
        if lens.k1 or lens.k2:
            corner = math.hypot(img.width_px / 2.0, img.height_px / 2.0) / f_px
            if not _distortion_invertible(lens.k1, lens.k2, corner):
                raise ValueError(
                    f"sensor.lens: k1 {lens.k1:g}, k2 {lens.k2:g} fold the image back on itself before the "
                    f"corner (normalised radius {corner:.3f}); expected r (1 + k1 r^2 + k2 r^4) to grow with r "
                    "up to the corner")
        if sensor.compression.codec == "h264" and (img.width_px % 2 or img.height_px % 2):
            raise ValueError(
                f"sensor.compression.codec: h264 (4:2:0) needs an even image size, got "
                f"{img.width_px}x{img.height_px}")
        tr = self.traffic
        if tr.density_per_lane_km or tr.cyclists_per_lane_km:
            step_px = tr.speed_range_mps[1] / img.fps / gsd
            limit_px = MAX_VEHICLE_STEP_FRACTION * side_px
            if step_px > limit_px:
                raise ValueError(
                    f"traffic.speed_range_mps: a vehicle at {tr.speed_range_mps[1]:g} m/s moves {step_px:.1f} px "
                    f"per frame at {img.fps:g} fps and {gsd:.3f} m/px; expected <= {limit_px:.1f} px "
                    f"({MAX_VEHICLE_STEP_FRACTION:g} of the image's smaller side): too fast for the scene")
        v = self.vehicles
        if v.count:

            top_mps = v.speed_range_mps[1]  # accelerating vehicles stop accelerating there
            step_px = top_mps / img.fps / gsd
            limit_px = MAX_VEHICLE_STEP_FRACTION * side_px
            if step_px > limit_px:
                raise ValueError(
                    f"vehicles.speed_range_mps: a vehicle at {top_mps:g} m/s moves {step_px:.1f} px per "
                    f"frame at {img.fps:g} fps and {gsd:.3f} m/px; expected <= {limit_px:.1f} px "
                    f"({MAX_VEHICLE_STEP_FRACTION:g} of the image's smaller side): too fast for the scene")
        return self


def _distortion_invertible(k1: float, k2: float, r_corner: float) -> bool:
    """Whether ``r_d = r (1 + k1 r^2 + k2 r^4)`` grows with r until it passes ``r_corner``.

    Then every distorted radius up to the image corner has exactly one undistorted radius.
    """
    r = np.linspace(0.0, 4.0 * r_corner, 4001)
    r_d = r * (1 + k1 * r**2 + k2 * r**4)
    slope = 1 + 3 * k1 * r**2 + 5 * k2 * r**4  # d r_d / d r
    past = np.nonzero(r_d >= r_corner)[0]
    return bool(past.size) and bool((slope[:past[0] + 1] > 0).all())


# -- loading ----------------------------------------------------------------------------

def _format_errors(err: ValidationError, source: str) -> str:
    lines = []
    for e in err.errors():
        loc = ".".join(str(p) for p in e["loc"])
        msg = e["msg"]
        if msg.startswith("Value error, "):
            msg = msg[len("Value error, "):]
        if e["type"] == "extra_forbidden":
            msg = "unknown key"
        got = e.get("input")
        shown = "" if isinstance(got, (dict, list)) or e["type"] == "extra_forbidden" else f" (got {got!r})"
        lines.append(f"  {loc}: {msg}{shown}" if loc else f"  {msg}{shown}")
    return f"scene spec {source}: invalid\n" + "\n".join(lines)


def _preset_paths() -> dict[str, Path]:
    return {p.stem: p for p in sorted(PRESET_DIR.glob("*.yaml"))}


def list_presets() -> dict[str, str]:
    """Built-in presets: name -> one-line description."""
    out = {}
    for name, path in _preset_paths().items():
        data = yaml.safe_load(path.read_text()) or {}
        out[name] = str(data.get("description", "")).strip().splitlines()[0] if data.get("description") else ""
    return out


def _set_dotted(data: dict, key: str, value: Any, source: str) -> None:
    parts = key.split(".")
    if not all(parts):
        raise SceneSpecError(f"scene spec {source}: override {key!r}: expected a dotted field name")
    node = data
    for i, p in enumerate(parts[:-1]):
        child = node.get(p)
        if child is None:
            child = node[p] = {}
        if not isinstance(child, dict):
            raise SceneSpecError(
                f"scene spec {source}: override {key!r}: {'.'.join(parts[:i + 1])} is not a section")
        node = child
    node[parts[-1]] = value


def _validate(data: Any, source: str) -> SceneSpec:
    if not isinstance(data, dict):
        raise SceneSpecError(f"scene spec {source}: expected a mapping at the top, got {type(data).__name__}")
    try:
        return SceneSpec.model_validate(data)
    except ValidationError as err:
        raise SceneSpecError(_format_errors(err, source)) from None


def load_scene_spec(name_or_path: str | os.PathLike | SceneSpec | dict,
                    overrides: dict[str, Any] | None = None) -> SceneSpec:
    """Load a spec from a preset name, a YAML file, a dict or a spec, then apply overrides.

    Parameters
    ----------
    name_or_path : str, path, dict or SceneSpec
        A preset name (see :func:`list_presets`), a path to a YAML file, or data.
    overrides : dict, optional
        Dotted field -> value, e.g. ``{"camera.jitter.roll_std_deg": 0.5, "seed": 3}``.

    Raises
    ------
    SceneSpecError
        Unknown preset (the message lists the valid ones), unreadable YAML, or an
        invalid field; the message names the source and the dotted field.
    """
    if isinstance(name_or_path, SceneSpec):
        source, data = f"<{name_or_path.name}>", name_or_path.model_dump(mode="json")
    elif isinstance(name_or_path, dict):
        source, data = "<dict>", json.loads(json.dumps(name_or_path))
    else:
        text = os.fspath(name_or_path)
        presets = _preset_paths()
        if text in presets:
            path = presets[text]
            source = f"preset {text!r} ({path})"
        else:
            path = Path(text)
            source = str(path)
            if not path.is_file():
                looks_like_file = path.suffix in (".yaml", ".yml") or os.sep in text
                what = "no such file" if looks_like_file else "unknown preset"
                raise SceneSpecError(
                    f"scene spec {text!r}: {what}; valid presets: {', '.join(presets)} "
                    "(or give a path to a .yaml file)")
        try:
            data = yaml.safe_load(path.read_text())
        except yaml.YAMLError as err:
            raise SceneSpecError(f"scene spec {source}: not valid YAML: {err}") from None
        if data is None:
            data = {}
        if text in presets and isinstance(data, dict):
            data.setdefault("name", text)
    if overrides:
        if not isinstance(data, dict):
            raise SceneSpecError(f"scene spec {source}: expected a mapping at the top")
        for key, value in overrides.items():
            _set_dotted(data, key, value, source)
        source = f"{source} with overrides {sorted(overrides)}"
    return _validate(data, source)


def spec_to_yaml(spec: SceneSpec) -> str:
    """The resolved spec (every field, with its seed) as YAML."""
    return yaml.safe_dump(spec.model_dump(mode="json"), sort_keys=False)


def spec_hash(spec: SceneSpec) -> str:
    """Content hash of the resolved spec: sha256 of its canonical JSON, 16 hex digits."""
    canonical = json.dumps(spec.model_dump(mode="json"), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(canonical.encode()).hexdigest()[:16]
