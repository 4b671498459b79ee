"""High-order truth plant: CommonRoad multi-body port, physics, ground truth, envs, bad input."""

import math

import gymnasium as gym
import numpy as np
import pytest

import tire_learning_env
from tire_learning_env.high_order import (
    COMMONROAD_TIRE,
    COMMONROAD_VEHICLE2,
    HighOrderConfig,
    MultiBodyParams,
    MultiBodyPlant,
    bmw_320i,
    effective_cornering_stiffness,
    simulate_high_order,
    static_wheel_loads,
    steady_state_cornering,
    tire_lateral_force,
    true_cornering_stiffness,
)
from tire_learning_env.high_order import _mb_kernels as K
from tire_learning_env.high_order.plant import parameter_vector, static_state, tire_vector
from tire_learning_env.params import CameraParams, DriverParams, ParameterError
from tire_learning_env.roads import PiecewiseCurvatureRoad
from tire_learning_env.simulation import Simulator


def _params_with(**changes):
    d = bmw_320i().to_dict()
    tire = dict(d["tire"])
    for key, value in changes.items():
        if key in tire:
            tire[key] = value
        else:
            d[key] = value
    d["tire"] = tire
    return MultiBodyParams.from_dict(d)


def _random_states(rng, p, count):
    """Random multi-body states around straight driving (CommonRoad's own init_mb)."""
    from vehiclemodels.init_mb import init_mb

    scale = np.array(
        [10, 10, 0.1, 0, 1, 0.3, 0.03, 0.1, 0.02, 0.1, 1.0, 0.01, 0.05, 0.03, 0.1, 1.0, 0.003, 0.05,
         0.03, 0.1, 1.0, 0.003, 0.05, 2, 2, 2, 2, 0.002, 0.002]
    )  # fmt: skip
    for k in range(count):
        speed = rng.uniform(0.02, 0.09) if k % 25 == 0 else rng.uniform(3.0, 45.0)  # also the kinematic branch
        x = np.array(init_mb([0, 0, 0.0, speed, 0, 0, 0], p)) + scale * rng.uniform(-1, 1, 29)
        if k % 17 == 0:
            x[23] = -abs(x[23])  # a negative wheel spin (CommonRoad zeroes its derivative)
        yield x, [rng.uniform(-0.6, 0.6), rng.uniform(-15, 15)]


# -- the port ------------------------------------------------------------------------------
def test_port_equals_commonroad_vehicle_dynamics_mb():
    cr = pytest.importorskip("vehiclemodels.vehicle_dynamics_mb")
    from vehiclemodels.parameters_vehicle2 import parameters_vehicle2

    p = parameters_vehicle2()
    par = parameter_vector(bmw_320i(), HighOrderConfig(relaxation_length=0.0))
    ty = tire_vector(bmw_320i().tire, symmetric=False)
    f = np.zeros(K.N_STATE)
    aux = np.zeros(K.N_AUX)
    xx = np.zeros(K.N_STATE)
    for x, u in _random_states(np.random.default_rng(0), p, 400):
        want = np.array(cr.vehicle_dynamics_mb(list(x), list(u), p))
        xx[:29] = x
        K.mb_rhs(xx, u[0], u[1], par, ty, False, f, aux)
        np.testing.assert_allclose(f[:29], want, rtol=1e-12, atol=1e-12)


def test_the_named_layouts_match_their_names():
    """The port indexes state, wheels and camera errors by name: each name is the entry it says."""
    from tire_learning_env.dynamics import StateIndex

    assert (K.N_MB, K.N_STATE, len(K.STATE_NAMES)) == (29, 34, K.N_STATE)
    named = {"S_X": "x", "S_Y": "y", "S_DELTA": "delta", "S_VX": "vx", "S_PSI": "psi", "S_R": "yaw_rate",
             "S_VY": "vy", "S_Z": "z", "S_ROLL_F": "roll_f", "S_VY_R": "vy_r", "S_OMEGA_LF": "omega_lf",
             "S_OMEGA_RR": "omega_rr", "S_DY_F": "delta_y_f", "S_DY_R": "delta_y_r", "S_LAG_LF": "lag_alpha_lf",
             "S_LAG_RR": "lag_alpha_rr", "S_SPEED_INT": "speed_integral"}  # fmt: skip
    for const, state_name in named.items():
        assert K.STATE_NAMES[getattr(K, const)] == state_name, const
    assert (K.W_LF, K.W_RF, K.W_LR, K.W_RR, K.N_WHEELS) == (0, 1, 2, 3, 4)
    assert K.AUX_GAMMA + K.N_WHEELS == K.N_AUX
    assert (K.ERR_E1, K.ERR_E1_DOT, K.ERR_E2, K.ERR_E2_DOT) == (StateIndex.E1, StateIndex.E1_DOT, StateIndex.E2,
                                                               StateIndex.E2_DOT)  # fmt: skip


def test_tire_functions_equal_commonroad():
    tm = pytest.importorskip("vehiclemodels.utils.tire_model")
    from vehiclemodels.parameters_vehicle2 import parameters_vehicle2

    pt = parameters_vehicle2().tire
    ty = tire_vector(bmw_320i().tire)
    rng = np.random.default_rng(1)
    for _ in range(300):
        kappa, alpha, gamma = rng.uniform(-0.2, 0.2), rng.uniform(-0.3, 0.3), rng.uniform(-0.05, 0.05)
        fz = rng.uniform(500.0, 6000.0)
        assert K.pac_longitudinal(kappa, gamma, fz, ty) == pytest.approx(tm.formula_longitudinal(kappa, gamma, fz, pt), rel=1e-13)
        fy0, mu = K.pac_lateral(alpha, gamma, fz, ty)
        want_fy0, want_mu = tm.formula_lateral(alpha, gamma, fz, pt)
        assert (fy0, mu) == pytest.approx((want_fy0, want_mu), rel=1e-13)
        fx0 = tm.formula_longitudinal(kappa, gamma, fz, pt)
        assert K.pac_longitudinal_comb(kappa, alpha, fx0, ty) == pytest.approx(tm.formula_longitudinal_comb(kappa, alpha, fx0, pt), rel=1e-12)
        assert K.pac_lateral_comb(kappa, alpha, gamma, mu, fz, fy0, ty) == pytest.approx(
            tm.formula_lateral_comb(kappa, alpha, gamma, want_mu, fz, want_fy0, pt), rel=1e-12, abs=1e-9
        )


def test_embedded_parameter_set_equals_commonroad_vehicle2():
    pytest.importorskip("vehiclemodels")
    assert MultiBodyParams.from_commonroad(2) == bmw_320i()


# -- static state and ground truth ------------------------------------------------------------
def test_static_state_is_an_equilibrium():
    p = bmw_320i()
    plant = MultiBodyPlant("straight", p, HighOrderConfig(relaxation_length=0.0))
    x = static_state(p, 30.0)
    f = np.zeros(K.N_STATE)
    aux = np.zeros(K.N_AUX)
    K.plant_rhs(x, 0.0, 30.0, 0.0, plant.par, plant.ty, f, aux)
    # everything but the position and the wheel spins (PAC2002's p_hx1 shift) is at rest
    settled = [i for i in range(K.N_MB) if i not in (K.S_X, K.S_OMEGA_LF, K.S_OMEGA_RF, K.S_OMEGA_LR, K.S_OMEGA_RR)]
    assert np.abs(f[settled]).max() < 0.01
    np.testing.assert_allclose(aux[K.AUX_FZ : K.AUX_FZ + 4], np.repeat(static_wheel_loads(p), 2), rtol=1e-12)
    np.testing.assert_allclose(aux[K.AUX_GAMMA : K.AUX_GAMMA + 4], 0.0, atol=1e-15)


def test_true_cornering_stiffness_is_the_slope_of_the_own_tire_curve():
    p = bmw_320i()
    cf, cr = true_cornering_stiffness(p)
    fz_f, fz_r = static_wheel_loads(p)
    h = 1e-6
    for c, fz in ((cf, fz_f), (cr, fz_r)):
        for symmetric in (True, False):
            slope = (tire_lateral_force(h, fz, p.tire, symmetric) - tire_lateral_force(-h, fz, p.tire, symmetric)) / (2 * h)
            assert slope == pytest.approx(c, rel=1e-7)
    # and the same slope from CommonRoad's own tire functions
    tm = pytest.importorskip("vehiclemodels.utils.tire_model")
    from vehiclemodels.parameters_vehicle2 import parameters_vehicle2

    pt = parameters_vehicle2().tire

    def commonroad_fy(alpha_cr, fz):
        fy0, mu = tm.formula_lateral(alpha_cr, 0.0, fz, pt)
        return tm.formula_lateral_comb(0.0, alpha_cr, 0.0, mu, fz, fy0, pt)

    slope = -(commonroad_fy(h, fz_f) - commonroad_fy(-h, fz_f)) / (2 * h)
    assert slope == pytest.approx(cf, rel=1e-7)
    assert (cf, cr) == pytest.approx((64139.5126, 53408.9607), rel=1e-9)
    plant = MultiBodyPlant("straight", p)
    assert (plant.vehicle.Cf, plant.vehicle.Cr) == (cf, cr)
    assert plant.true_cornering_stiffness() == (cf, cr)
    assert plant.true_axle_curve(np.array([1e-6]), "front")[0] == pytest.approx(2 * cf * 1e-6, rel=1e-6)


def test_ground_truth_follows_the_documented_conventions():
    plant = MultiBodyPlant("study1")
    for _ in range(200):
        af, ar, fyf, fyr, r, ay = plant.step(0.01, 1e-3, None, None, 30.0, 0.0)
    w = plant.wheel_output()
    x = plant.x  # after the step; the truth is from its start, so recompute from output()
    out = plant.output()
    d = x[K.S_DELTA]
    assert out.force[0] == pytest.approx((w["fy"][0] + w["fy"][1]) * math.cos(d) + (w["fx"][0] + w["fx"][1]) * math.sin(d), rel=1e-2)
    vx, vy, rr = x[K.S_VX], x[K.S_VY], x[K.S_R]
    assert out.slip[0] == pytest.approx(d - (vy + plant.params.a * rr) / vx, rel=1e-12)
    assert out.slip[1] == pytest.approx((plant.params.b * rr - vy) / vx, rel=1e-12)
    assert out.force[0] > 0 and out.slip[0] > 0  # left steer: positive slip, force to the left
    np.testing.assert_allclose(out.force_nonlinear, out.force - out.slip * 2 * np.array([plant.vehicle.Cf, plant.vehicle.Cr]))


def test_reset_places_the_car_at_the_requested_error_state():
    plant = MultiBodyPlant("study1")
    xi = np.array([0.4, 0.1, 0.02, -0.01])
    plant.reset(xi)
    np.testing.assert_allclose(plant.state, xi, atol=1e-12)


def test_camera_errors_match_a_brute_force_projection_on_a_curve():
    plant = MultiBodyPlant("study1")
    sim = Simulator(plant, plant.road, CameraParams(), DriverParams())
    sim.reset(np.random.default_rng(0))
    sim.advance(16000, steering_offset=0.01)  # on the R = 300 m arc, pushed off the centre line
    geo = plant.road.geometry(plant.s + 50.0, ds=0.001)
    X, Y = plant.x[K.S_X], plant.x[K.S_Y]
    i = np.argmin((geo["x"] - X) ** 2 + (geo["y"] - Y) ** 2)
    th = geo["heading"][i]
    e1 = -(X - geo["x"][i]) * math.sin(th) + (Y - geo["y"][i]) * math.cos(th)
    assert abs(plant.s - geo["s"][i]) < 2e-3
    assert plant.state[0] == pytest.approx(e1, abs=1e-5)
    assert plant.state[2] == pytest.approx(plant.x[K.S_PSI] - th, abs=1e-5)
    assert abs(plant.state[0]) > 0.02  # the test actually probes an offset (about 4 cm)
    assert abs(plant.s - sim.s) < 0.1  # the simulator's distance (vx t) and the true one agree


# -- physics ----------------------------------------------------------------------------------
def test_straight_line_driving_stays_straight():
    log = simulate_high_order("straight", 20.0)
    xi = log.truth["true_state"]
    assert np.abs(xi[:, 0]).max() < 1e-3  # measured 1.5e-4 m
    assert np.abs(xi[:, 2]).max() < 1e-4  # measured 1.2e-5 rad
    assert np.abs(log.sensors["delta"]).max() < 1e-4
    assert np.abs(log.truth["true_force"]).max() < 20.0
    # open loop, zero steering: only PAC2002's small longitudinal-slip side force (~2.4 N) pulls
    plant = MultiBodyPlant("straight")
    for _ in range(5000):
        plant.step(0.0, 1e-3, None, None, 30.0, 0.0)
    assert abs(plant.x[K.S_R]) < 1e-4
    assert abs(plant.state[2]) < 1e-3
    assert plant.x[K.S_VX] == pytest.approx(30.0, abs=1e-3)


@pytest.mark.parametrize("radius", [250.0, -300.0])
def test_steady_state_cornering_lateral_acceleration_is_v2_over_r(radius):
    ss = steady_state_cornering(radius, duration=8.0)
    assert ss["ay"] == pytest.approx(ss["vx"] ** 2 / radius, rel=2e-3)
    assert ss["yaw_rate"] == pytest.approx(ss["vx"] / radius, rel=2e-3)
    assert ss["vx"] == pytest.approx(30.0, abs=0.02)  # the PI speed controller holds 30 m/s
    assert abs(ss["e1"]) < 0.05


def test_effective_axle_stiffness_is_the_tire_stiffness_plus_camber_thrust():
    """Without CommonRoad's camber terms a bicycle model sees exactly the tire stiffness."""
    no_camber = _params_with(p_hy3=0.0, p_vy3=0.0)
    cf, cr = effective_cornering_stiffness(no_camber)
    tf, tr = true_cornering_stiffness(no_camber)
    assert cf == pytest.approx(tf, rel=5e-3) and cr == pytest.approx(tr, rel=5e-3)
    cf, cr = effective_cornering_stiffness()
    assert cf / tf == pytest.approx(1.137, abs=0.01)  # roll-camber thrust stiffens both axles
    assert cr / tr == pytest.approx(1.080, abs=0.01)


def test_relaxation_length_lags_the_slip_by_sigma_over_vx():
    sigma = 0.45
    plant = MultiBodyPlant("straight", config=HighOrderConfig(relaxation_length=sigma), record=True)
    for _ in range(5):
        plant.step(0.0, 1e-3, None, None, 30.0, 0.0)
    for _ in range(100):
        plant.step(0.01, 1e-3, None, None, 30.0, 0.0)  # steering step
    h = plant.history()
    kin, lag = h["alpha_kinematic"][:, 0], h["alpha_lagged"][:, 0]
    t = h["t"] - h["t"][5]
    tau = sigma / 30.0
    j = np.searchsorted(t, tau)
    frac = (lag[j] - lag[4]) / (kin[5] - kin[4])
    assert frac == pytest.approx(1 - math.exp(-1), abs=0.06)
    # the force lags too: less front force 10 ms after the step than without relaxation
    instant = MultiBodyPlant("straight", config=HighOrderConfig(relaxation_length=0.0))
    for k in range(15):
        out_i = instant.step(0.0 if k < 5 else 0.01, 1e-3, None, None, 30.0, 0.0)
    lagged = MultiBodyPlant("straight", config=HighOrderConfig(relaxation_length=sigma))
    for k in range(15):
        out_l = lagged.step(0.0 if k < 5 else 0.01, 1e-3, None, None, 30.0, 0.0)
    assert out_l[2] < 0.6 * out_i[2]


def test_lane_changes_show_force_slip_hysteresis():
    log = simulate_high_order("lane_changes", 12.0)
    slip, force = log.truth["true_slip"][:, 0], log.truth["true_force"][:, 0]
    # at the same slip the force differs between loading and unloading (Fig. 2 of the paper)
    rising = np.gradient(slip) > 0
    band = np.abs(slip - 0.004) < 4e-4
    assert band[rising].any() and band[~rising].any()
    gap = abs(force[band & rising].mean() - force[band & ~rising].mean())
    assert gap > 20.0


# -- plant interface, bad input --------------------------------------------------------------
def test_blow_up_names_time_and_state():
    plant = MultiBodyPlant("straight")
    for _ in range(3):
        plant.step(0.0, 1e-3, None, None, 30.0, 0.0)
    with pytest.raises(FloatingPointError, match=r"t=0\.0030 s.*vx=30"):
        plant.step(float("nan"), 1e-3, None, None, 30.0, 0.0)


def test_missing_unknown_and_inconsistent_parameters_are_named():
    data = dict(COMMONROAD_VEHICLE2, tire=dict(COMMONROAD_TIRE))
    del data["K_zt"]
    with pytest.raises(ParameterError, match="K_zt"):
        MultiBodyParams.from_dict(data)
    tire = dict(COMMONROAD_TIRE)
    del tire["p_ky1"]
    with pytest.raises(ParameterError, match="p_ky1"):
        MultiBodyParams.from_dict(dict(COMMONROAD_VEHICLE2, tire=tire))
    with pytest.raises(ParameterError, match="frobnicate"):
        MultiBodyParams.from_dict(dict(COMMONROAD_VEHICLE2, tire=dict(COMMONROAD_TIRE), frobnicate=1.0))
    with pytest.raises(ParameterError, match=r"MultiBodyParams\.m .*m_s \+ m_uf \+ m_ur"):
        _params_with(m=1500.0)
    with pytest.raises(ParameterError, match="p_ky1"):
        _params_with(p_ky1=21.92)
    with pytest.raises(ParameterError, match="K_zt"):
        _params_with(K_zt=-1.0)
    with pytest.raises(ParameterError, match="T_sb"):
        _params_with(T_sb=1.5)
    with pytest.raises(ParameterError, match="steering"):
        MultiBodyParams.from_dict(dict(COMMONROAD_VEHICLE2, tire=dict(COMMONROAD_TIRE), steering={"min": -1.0, "max": 1.0, "v_min": -0.4}))
    with pytest.raises(ParameterError, match="h_s"):
        _params_with(h_s=float("nan"))
    with pytest.raises(ParameterError, match="relaxation_length"):
        HighOrderConfig(relaxation_length=-0.1)

    class Incomplete:
        pass

    with pytest.raises(ParameterError, match="missing field"):
        MultiBodyParams.from_commonroad(Incomplete())


# -- environments ---------------------------------------------------------------------------
def test_env_has_the_base_env_spaces_and_info_keys():
    base = gym.make("TireLearning-LaneChange-v0")
    high = gym.make("TireLearning-HighOrderLaneChange-v0")
    assert base.observation_space == high.observation_space and base.action_space == high.action_space
    _, info_b = base.reset(seed=0)
    _, info_h = high.reset(seed=0)
    assert info_b.keys() == info_h.keys()
    _, _, _, _, info_b = base.step(np.zeros(1, np.float32))
    _, _, _, _, info_h = high.step(np.zeros(1, np.float32))
    assert info_b.keys() == info_h.keys()
    assert info_b["sensor_log"].keys() == info_h["sensor_log"].keys()
    assert info_b["truth_log"].keys() == info_h["truth_log"].keys()
    for key in info_h["truth_log"]:
        assert info_h["truth_log"][key].shape == info_b["truth_log"][key].shape
    env = high.unwrapped
    assert isinstance(env.plant, MultiBodyPlant)
    assert env.vehicle == env.plant.vehicle  # the driver and estimators get the equivalent bicycle
    np.testing.assert_array_equal(info_h["true_state"], env.plant.state)


def test_same_seed_same_rollout():
    camera = tire_learning_env.CameraParams.paper_noise(rate=20.0)

    def rollout(seed):
        env = gym.make("TireLearning-HighOrderLaneChange-v0", camera=camera)
        env.reset(seed=seed)
        out = []
        for k in range(40):
            obs, *_, info = env.step(np.array([0.01 * math.sin(0.3 * k)], np.float32))
            out.append(np.concatenate([obs, info["true_state"]]))
        return np.array(out)

    np.testing.assert_array_equal(rollout(3), rollout(3))
    assert not np.allclose(rollout(3), rollout(4))


def test_env_rejects_bicycle_tire_arguments_and_unknown_keys():
    with pytest.raises(TypeError, match="tire_model"):
        gym.make("TireLearning-HighOrderCornering-v0", tire_model="linear")
    with pytest.raises(ParameterError, match="effects"):
        gym.make("TireLearning-HighOrderCornering-v0", config={"effects": {}})
    with pytest.raises(ParameterError, match="relaxation"):
        gym.make("TireLearning-HighOrderCornering-v0", high_order_config={"relaxation": 0.3})
    env = gym.make("TireLearning-HighOrderCornering-v0", config={"high_order_config": {"relaxation_length": 0.3}})
    assert env.unwrapped.plant.config.relaxation_length == 0.3


def test_plant_runs_on_any_road_object():
    road = PiecewiseCurvatureRoad((0.0, 100.0, 130.0, 1e4), (0.0, 0.0, 1 / 400.0, 1 / 400.0))
    log = simulate_high_order(road, 8.0)
    assert np.abs(log.truth["true_state"][:, 0]).max() < 0.1
    assert log.truth["true_force"][-1].sum() > 0


def test_effective_reference_curve_and_stiffness():
    plant = MultiBodyPlant("lane_changes")
    cf, cr = plant.true_cornering_stiffness("effective")
    assert (cf, cr) == pytest.approx((72933.0, 57658.0), rel=2e-3)
    h = 2e-4
    for axle, c in (("front", cf), ("rear", cr)):
        f = plant.true_axle_curve(np.array([-h, h]), axle, reference="effective")
        assert (f[1] - f[0]) / (2 * h) == pytest.approx(2 * c, rel=0.01)
        # above the tire curve at the same slip (camber thrust), continuous beyond the circles
        a = np.linspace(-0.06, 0.06, 2401)
        eff, tire = plant.true_axle_curve(a, axle, "effective"), plant.true_axle_curve(a, axle)
        assert np.all(eff[a > 0.002] > tire[a > 0.002])
        assert np.abs(np.diff(eff)).max() < 3 * np.abs(np.diff(tire)).max()
    with pytest.raises(ParameterError, match="reference"):
        plant.true_axle_curve(0.01, "front", reference="steady")
