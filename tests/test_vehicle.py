import math

import numpy as np
import pytest
import torch

from parknss import signals
from parknss.vehicle import (
    VehicleGeometry,
    arc_step,
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


def _circle(x0, y0, h0, kappa, s):
    """The analytic pose after arc length s on a circle of curvature kappa (!= 0)."""
    r = 1.0 / kappa
    h = h0 + kappa * s
    return x0 + r * (np.sin(h) - np.sin(h0)), y0 - r * (np.cos(h) - np.cos(h0)), h


def test_arc_step_is_the_analytic_circle_and_line():
    rng = np.random.default_rng(0)
    x0, y0, h0 = rng.uniform(-5, 5, 200), rng.uniform(-5, 5, 200), rng.uniform(-4, 4, 200)
    kappa = rng.uniform(-0.25, 0.25, 200)
    s = rng.uniform(-6, 6, 200)  # signed: reverse included, up to 1.5 rad of turn
    got = np.array(arc_step(x0, y0, h0, s, kappa * s))
    want = np.array(_circle(x0, y0, h0, kappa, s))
    np.testing.assert_allclose(got, want, atol=1e-12)
    for i in range(20):  # the scalar (math) path is the same formula
        one = arc_step(
            float(x0[i]), float(y0[i]), float(h0[i]), float(s[i]), float(kappa[i] * s[i])
        )
        assert all(isinstance(v, float) for v in one)
        np.testing.assert_allclose(one, got[:, i], atol=1e-14)
    # straight (kappa = 0) in both paths, and turning on the spot (ds = 0)
    assert arc_step(1.0, 2.0, math.pi / 2, -0.5, 0.0) == pytest.approx((1.0, 1.5, math.pi / 2))
    np.testing.assert_allclose(
        np.array(arc_step(x0, y0, h0, s, 0.0 * s))[:2],
        [x0 + s * np.cos(h0), y0 + s * np.sin(h0)],
        atol=1e-12,
    )
    assert arc_step(1.0, 2.0, 0.3, 0.0, 0.4) == pytest.approx((1.0, 2.0, 0.7))
    # a tiny turn is the line to first order (no 0/0)
    x, y, h = arc_step(0.0, 0.0, 0.0, 1.0, 1e-14)
    assert (x, h) == pytest.approx((1.0, 1e-14)) and y == pytest.approx(5e-15, abs=1e-20)


def test_vehicle_yaml_gives_the_geometry_and_refuses_bad_files(tmp_path):
    """Issue 17: one car end to end starts with reading it (--vehicle FILE.yaml)."""
    import pytest

    from parknss.config import CONFIG_DIR
    from parknss.errors import ConfigError
    from parknss.vehicle import load_vehicle_geometry, same_geometry

    tpcap = load_vehicle_geometry(CONFIG_DIR / "tpcap_vehicle.yaml")
    assert tpcap.wheelbase == 2.8 and tpcap.width == 1.942 and tpcap.rear_overhang == 0.929
    assert tpcap.front_overhang == pytest.approx(0.96)
    assert math.radians(tpcap.steer_lock_deg / tpcap.steer_ratio) == pytest.approx(0.75, abs=1e-4)
    assert tpcap.min_turning_radius() == pytest.approx(2.8 / math.tan(0.75), rel=1e-3)
    alt = load_vehicle_geometry(CONFIG_DIR / "reference_vehicle_alt.yaml")  # a full vehicle file
    assert alt.wheelbase == 2.8 and same_geometry(alt, VehicleGeometry())
    bad = tmp_path / "car.yaml"
    bad.write_text("geometry:\n  wheelbase: 2.8\n  wheel_base: 2.7\n")
    with pytest.raises(ConfigError, match="unknown geometry key"):
        load_vehicle_geometry(bad)
    bad.write_text("geometry:\n  wheelbase: -1\n")
    with pytest.raises(ConfigError, match="positive"):
        load_vehicle_geometry(bad)
    with pytest.raises(ConfigError, match="not found"):
        load_vehicle_geometry(tmp_path / "none.yaml")
