import math

import numpy as np
import torch

from parknss import signals
from parknss.vehicle import (
    VehicleGeometry,
    min_turning_radius,
    road_wheel_angle,
    steering_ratio_at,
    yaw_rate_ref,
)

G = VehicleGeometry()


def test_yaw_rate_ref_matches_closed_form():
    vx, sw = 0.8, 240.0
    expected = vx / 3.0 * math.tan(math.radians(sw / 12.1))
    assert math.isclose(yaw_rate_ref(vx, sw, G), expected, rel_tol=1e-12)


def test_yaw_rate_ref_numpy_and_torch_agree():
    vx = np.linspace(-1, 1, 11)
    sw = np.linspace(-400, 400, 11)
    a = yaw_rate_ref(vx, sw, G)
    b = yaw_rate_ref(torch.tensor(vx), torch.tensor(sw), G).numpy()
    np.testing.assert_allclose(a, b, rtol=1e-12)
    # sign: reverse flips the yaw rate for the same steering
    np.testing.assert_allclose(yaw_rate_ref(-vx, sw, G), -a)


def test_nonlinear_rack_endpoints_and_monotone():
    assert math.isclose(steering_ratio_at(0.0, G), 13.0)
    assert math.isclose(steering_ratio_at(400.0, G), 12.1)
    sw = np.linspace(-400, 400, 2001)
    rw = road_wheel_angle(sw, G, nonlinear=True)
    assert np.all(np.diff(rw) > 0)


def test_min_turning_radius_about_4p6():
    r = min_turning_radius(G)
    assert 4.5 < r < 4.7


def test_unit_conversions_roundtrip():
    assert math.isclose(signals.ms_to_kmh(1.0), 3.6)
    assert math.isclose(signals.kmh_to_ms(signals.ms_to_kmh(0.37)), 0.37)
    np.testing.assert_allclose(signals.convert_to_schema(np.array([1.0]), "km/h", "vx"), [1 / 3.6])
    np.testing.assert_allclose(
        signals.convert_to_schema(np.array([0.1]), "MPa", "brake_pressure"), [1.0]
    )
    assert signals.moving_mask(np.array([0.1, 0.2, -0.5])).tolist() == [False, True, True]
