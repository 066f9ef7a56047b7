"""Simulation settings (physics, servos, camera) and domain knobs, as validated dataclasses.

`SimConfig` is what the world is built with; `DomainKnobs` are the evaluation knobs of
DESIGN.md section 7 (ball mass, friction, gravity, detection noise, latency, lighting),
drawn reproducibly from a seed by `DomainKnobs.sample(domain, seed)`. No ROS import.
"""
from __future__ import annotations

import math
import random
from dataclasses import dataclass, field, fields, replace
from typing import Tuple

from ball_balance.plate_geometry import BALL_MASS_KG, BALL_RADIUS_M, ROLLING_FACTOR_SHELL, ROLLING_FACTOR_SOLID


class SimConfigError(ValueError):
    """A simulation setting is out of range (the message names it)."""


@dataclass(frozen=True)
class CameraConfig:
    """The fixed overhead camera: it looks straight down at the plate centre at home pose.

    Image axes match the plate frame at home: image right = plate +x, image up = plate +y.
    """

    width_px: int = 640
    height_px: int = 480
    fovy_deg: float = 45.0          # vertical field of view; fx = fy (square pixels)
    height_above_plate_m: float = 0.65
    rate_hz: float = 30.0
    antialias_samples: int = 0      # MSAA samples of the offscreen buffer: 4 costs ~2.5x render time

    def __post_init__(self):
        for name in ("width_px", "height_px"):
            value = getattr(self, name)
            if not isinstance(value, int) or value <= 0 or value > 4096:
                raise SimConfigError(f"camera {name} = {value!r} must be an integer in 1..4096")
        _check_range("camera fovy_deg", self.fovy_deg, 5.0, 150.0)
        _check_range("camera height_above_plate_m", self.height_above_plate_m, 0.1, 5.0)
        _check_range("camera rate_hz", self.rate_hz, 0.0, 1000.0)
        if self.antialias_samples not in (0, 1, 2, 4, 8):
            raise SimConfigError(f"camera antialias_samples = {self.antialias_samples!r} must be 0, 1, 2, 4 or 8")


@dataclass(frozen=True)
class SimConfig:
    """Physics and servo settings. Derived values are properties, not extra settings."""

    physics_dt_s: float = 0.001     # MuJoCo timestep (1-2 ms)
    servo_lag_s: float = 0.005      # joint servo time constant: 2 zeta / omega_n, critically damped
    ball_radius_m: float = BALL_RADIUS_M
    ball_shell: bool = True         # thin shell (I = 2/3 m r^2) or solid (2/5 m r^2)
    rolling_friction_m: float = 2e-6  # MuJoCo rolling friction (lever arm, m): tiny, so it rolls
    torsional_friction_m: float = 1e-4
    camera: CameraConfig = field(default_factory=CameraConfig)

    def __post_init__(self):
        _check_range("physics_dt_s", self.physics_dt_s, 1e-4, 0.005)
        _check_range("servo_lag_s", self.servo_lag_s, 5e-4, 0.1)
        _check_range("ball_radius_m", self.ball_radius_m, 0.005, 0.1)
        _check_range("rolling_friction_m", self.rolling_friction_m, 0.0, 0.01)
        _check_range("torsional_friction_m", self.torsional_friction_m, 0.0, 0.01)
        if self.servo_omega_rad_s * self.physics_dt_s > 1.0:
            raise SimConfigError(f"servo_lag_s = {self.servo_lag_s} is too short for physics_dt_s = "
                                 f"{self.physics_dt_s} (need servo_lag_s >= 2 * physics_dt_s)")

    @property
    def servo_omega_rad_s(self) -> float:
        """Servo natural frequency for the lag: omega_n = 2 zeta / lag with zeta = 1."""
        return 2.0 / self.servo_lag_s

    @property
    def rolling_factor(self) -> float:
        """k in x'' = k g sin(tilt) for this ball rolling without slipping."""
        return ROLLING_FACTOR_SHELL if self.ball_shell else ROLLING_FACTOR_SOLID


@dataclass(frozen=True)
class DomainKnobs:
    """One evaluation domain's physical and sensing values (DESIGN.md section 7)."""

    ball_mass_kg: float = BALL_MASS_KG
    ball_friction: float = 0.4          # ball-plate sliding friction coefficient
    gravity_scale: float = 1.0
    detection_noise_m: float = 0.0      # std of the truth-fed detection noise, plate frame
    latency_s: float = 0.0              # camera-to-command latency, added to joint commands
    light_scale: float = 1.0            # directional light intensity factor
    exposure: float = 1.0               # image gain after rendering

    def __post_init__(self):
        _check_range("ball_mass_kg", self.ball_mass_kg, 1e-4, 1.0)
        _check_range("ball_friction", self.ball_friction, 0.001, 5.0)
        _check_range("gravity_scale", self.gravity_scale, 0.0, 5.0)
        _check_range("detection_noise_m", self.detection_noise_m, 0.0, 0.1)
        _check_range("latency_s", self.latency_s, 0.0, 1.0)
        _check_range("light_scale", self.light_scale, 0.0, 5.0)
        _check_range("exposure", self.exposure, 0.05, 5.0)

    @staticmethod
    def sample(domain: str, seed: int) -> DomainKnobs:
        """The knobs of `domain` (see DOMAINS), random parts drawn from `seed` (reproducible)."""
        if domain not in DOMAINS:
            raise SimConfigError(f"unknown domain '{domain}': expected one of {sorted(DOMAINS)}")
        rng = random.Random(f"{domain}/{seed}")
        values = {}
        for name, spec in DOMAINS[domain].items():
            values[name] = rng.uniform(*spec) if isinstance(spec, tuple) else spec
        return replace(DomainKnobs(), **values)

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


# domain -> {knob: value or (low, high) drawn uniformly}
_FULL_DR = {
    "ball_mass_kg": (0.0022, 0.0050), "ball_friction": (0.05, 1.2), "gravity_scale": (0.5, 1.5),
    "detection_noise_m": (0.0, 0.003), "latency_s": (0.03, 0.15), "light_scale": (0.6, 1.4),
    "exposure": (0.7, 1.3),
}
DOMAINS = {
    "standard": {},
    "slippery": {"ball_friction": 0.05},
    "sticky": {"ball_friction": 1.2},
    "heavy_ball": {"ball_mass_kg": 0.0050},
    "low_gravity": {"gravity_scale": 0.5},
    "high_gravity": {"gravity_scale": 1.5},
    "noisy_vision": {"detection_noise_m": 0.003},
    "high_latency": {"latency_s": (0.03, 0.15)},
    "full_dr": _FULL_DR,
}


def _check_range(name: str, value: float, low: float, high: float) -> None:
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value) \
            or not low <= value <= high:
        raise SimConfigError(f"{name} = {value!r} must be a finite number in [{low}, {high}]")


def camera_intrinsics(camera: CameraConfig) -> Tuple[float, float, float, float]:
    """(fx, fy, cx, cy) in pixels of the pinhole model matching MuJoCo's rendered fovy.

    OpenCV convention: pixel (u, v) has its centre at integer coordinates, so the optical
    axis hits (W - 1) / 2, (H - 1) / 2.
    """
    f = 0.5 * camera.height_px / math.tan(math.radians(camera.fovy_deg) / 2.0)
    return f, f, (camera.width_px - 1) / 2.0, (camera.height_px - 1) / 2.0
