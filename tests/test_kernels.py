"""The compiled control law against its numpy formulation, and no compilation inside a tick.

The oracle (``tests/numpy_law.py``) is the law as it was written in numpy
before it was compiled (``controller/control/kernels.py``): the same
equations, one numpy expression each. Every kernel must agree with it to rounding on random
states, with and without a force axis, a speed brake, gravity.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
import zlib

import numpy as np
import pinocchio as pin
import pytest

from arm.robot_model import RobotModel
from controller.control import demand_kernels, kernels, limit_kernels, records
from controller.control.impedance import (
    Kinematics,
    Reference,
    TaskShaping,
    impedance_torque,
    task_modes,
    task_stiffness,
)
from controller.control.limits import LIMIT_SETTINGS, TorqueShaper, limits_record
from controller.control.params import ImpedanceParams
from controller.control.watch import DisturbanceWatch

from .numpy_law import numpy_kinematics, numpy_law, numpy_modes


@pytest.fixture
def rng(request):
    """A generator of the test's own, seeded by its id: a failure reproduces whichever worker ran it."""
    return np.random.default_rng(zlib.crc32(request.node.nodeid.encode()))


@pytest.fixture(scope="module")
def model():
    return RobotModel()


def _random_state(model, rng):
    lim = model.limits
    q = lim.q_min + (lim.q_max - lim.q_min) * rng.uniform(0.15, 0.85, model.nq)
    return q, rng.normal(0.0, 0.5, model.nq)


# ---------------------------------------------------------------------------------------------- the kernels
@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-5, 1e-3, 0.4, 1.5, 2.9, np.pi - 2e-3, np.pi - 1e-5, np.pi])
def test_log3_matches_pinocchio_over_the_whole_range(angle, rng):
    for _ in range(20):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        R = pin.exp3(angle * axis)
        out = np.zeros(3)
        kernels.log3_into(R, out)
        ref = pin.log3(R)
        if angle > np.pi - 1e-3:  # at pi, w and -w are the same rotation
            assert np.allclose(pin.exp3(out), R, atol=1e-9) and abs(np.linalg.norm(out) - angle) < 1e-6
        else:
            np.testing.assert_allclose(out, ref, atol=1e-12)


def test_spd_inverse_matches_numpy_and_refuses_an_indefinite_matrix(rng):
    for _ in range(50):
        X = rng.normal(size=(6, 6))
        A = X @ X.T + 1e-3 * np.eye(6)
        out, L = np.zeros((6, 6)), np.zeros((6, 6))
        assert kernels.spd_inverse_into(A, out, L)
        np.testing.assert_allclose(out, np.linalg.inv(A), rtol=1e-9, atol=1e-9 * np.abs(np.linalg.inv(A)).max())
    assert not kernels.spd_inverse_into(-np.eye(6), out, L)


def test_kinematics_equal_the_numpy_formulation(model, rng):
    kin = Kinematics(model)
    for _ in range(30):
        q, dq = _random_state(model, rng)
        kin.update(q, dq)
        ref = numpy_kinematics(model, q, dq)
        for name, want in ref.items():
            got = getattr(kin, name)
            np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-10 * max(1.0, np.abs(want).max()),
                                       err_msg=name)


@pytest.mark.parametrize("axis", [False, True])
@pytest.mark.parametrize("extra", [False, True])
@pytest.mark.parametrize("gravity", [False, True])
def test_the_impedance_law_equals_the_numpy_formulation(model, axis, extra, gravity, rng):
    params = ImpedanceParams(nullspace_stiffness_nm_rad=30.0)
    kin = Kinematics(model)
    for _ in range(20):
        q, dq = _random_state(model, rng)
        kin.update(q, dq)
        ref = Reference(kin.p + rng.normal(0, 0.03, 3), pin.exp3(rng.normal(0, 0.3, 3)) @ kin.R,
                        rng.normal(0, 0.2, 6), rng.normal(0, 2.0, 6))
        n = rng.normal(size=3)
        shaping = TaskShaping(force_axis=n / np.linalg.norm(n) if axis else None, press_n=8.0,
                              normal_damping_1_s=20.0, stiffness_scale=0.7, max_position_error_m=0.02,
                              max_rotation_error_rad=0.2, extra_force_n=rng.normal(0, 5, 3) if extra else None,
                              posture_nm=rng.normal(0, 3, model.nq) if extra else None)
        modes = task_modes(kin.Lambda, task_stiffness(params, 0.7), params.damping_factor, 80.0)
        q_rest = q + rng.normal(0, 0.2, model.nq)
        terms = impedance_torque(model, q, dq, ref, params, q_rest, gravity, shaping, kin, modes)
        *want, slack = numpy_law(numpy_kinematics(model, q, dq), q, dq, ref, params, q_rest, gravity, shaping,
                                 modes)
        for got, w, name in zip((terms.tau_nm, terms.wrench_task, terms.pose_error, terms.twist_error,
                                 terms.tau_nullspace), want, ("tau", "F", "e", "de", "tau_null")):
            atol = 1e-9 * max(1.0, np.abs(w).max()) + slack.get(name, 0.0)  # + what the pose's conditioning allows
            np.testing.assert_allclose(got, w, rtol=1e-9, atol=atol, err_msg=name)


def test_task_modes_give_the_numpy_stiffness_and_damping(model, rng):
    kin = Kinematics(model)
    for cap in (40.0, 120.0, 1e6):
        q, dq = _random_state(model, rng)
        kin.update(q, dq)
        K = task_stiffness(ImpedanceParams())
        modes = task_modes(kin.Lambda, K, 0.8, cap)
        K_want, D_want = numpy_modes(kin.Lambda, K, 0.8, cap)
        np.testing.assert_allclose(modes.stiffness(), K_want, rtol=1e-8, atol=1e-8 * np.abs(K_want).max())
        np.testing.assert_allclose(modes.damping(), D_want, rtol=1e-8, atol=1e-8 * np.abs(D_want).max())


def test_limits_equal_the_numpy_formulation(model, rng):
    lim = model.limits
    n = model.nq
    for gravity in (False, True):
        shaper = TorqueShaper(lim.tau_max, 1000.0)
        prev = rng.normal(0, 20, n)
        shaper.prev[:] = prev
        q = lim.q_max - rng.uniform(0.0, 0.2, n)  # some joints inside the margin
        dq = rng.normal(0, 1.5, n)
        tau = rng.normal(0, 60, n)
        M_diag = rng.uniform(0.05, 2.0, n)
        g = rng.normal(0, 30, n)
        onset = 0.8 * lim.dq_max
        # numpy: repulsion, brake, then the rate limit on tau - g and the absolute limit on the sum
        lo_d = np.clip(lim.q_min + 0.1 - q, 0.0, None)
        hi_d = np.clip(q - (lim.q_max - 0.1), 0.0, None)
        want = tau + 300.0 * (lo_d - hi_d) - 10.0 * (np.minimum(lo_d / 0.1, 1) * np.minimum(dq, 0)
                                                     + np.minimum(hi_d / 0.1, 1) * np.maximum(dq, 0))
        want += -50.0 * np.maximum(np.abs(dq) - onset, 0.0) * np.sign(dq) * M_diag
        off = g if gravity else np.zeros(n)
        want = np.clip(want - off, prev - 1.0, prev + 1.0) + off
        want = np.clip(want, -lim.tau_max, lim.tau_max)
        got = tau.copy()
        limits = limits_record(lim.q_min, lim.q_max, lim.dq_max, onset, np.zeros(n),
                               **{**dict.fromkeys(LIMIT_SETTINGS, 0.0), "margin_rad": 0.1,
                                  "margin_stiffness_nm_rad": 300.0, "margin_damping_nm_s_rad": 10.0,
                                  "speed_brake_1_s": 50.0})
        hit = limit_kernels.limit_torque(got, q, dq, np.diag(M_diag), g, gravity, limits, shaper.rec, 1.0)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(shaper.prev, want - off, atol=1e-9)
        assert hit & 1  # 60 Nm from a random previous command is always more than 1 Nm away



def test_the_limits_press_nothing_along_the_board_normal_and_keep_the_rest(model, rng):
    """Pressing on a board, what the joint-limit repulsion and the speed brake add is made neutral along its normal:
    the task force of additions plus :func:`normal_neutral_into`'s torque has no component along it (numpy), its
    other components are the additions' own, and the kernel returns the force it took out. On random board 35 the
    elbow within the repulsion's margin pressed the pad with 15 N more than the regulator asked (20.6 N peak)."""
    lim = model.limits
    n = model.nq
    kin = Kinematics(model)
    onset = 0.6 * lim.dq_max
    limits = limits_record(lim.q_min, lim.q_max, lim.dq_max, onset, np.zeros(n),
                           **{**dict.fromkeys(LIMIT_SETTINGS, 0.0), "margin_rad": 0.12,
                              "margin_stiffness_nm_rad": 300.0, "margin_damping_nm_s_rad": 10.0,
                              "speed_brake_1_s": 50.0})
    for _ in range(20):
        q = lim.q_max - rng.uniform(0.0, 0.3, n)  # some joints inside the margin
        dq = rng.normal(0, 1.5, n)  # some over the brake's onset
        kin.update(q, dq)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        lo_d = np.clip(lim.q_min + 0.12 - q, 0.0, None)
        hi_d = np.clip(q - (lim.q_max - 0.12), 0.0, None)
        add = 300.0 * (lo_d - hi_d) - 10.0 * (np.minimum(lo_d / 0.12, 1) * np.minimum(dq, 0)
                                              + np.minimum(hi_d / 0.12, 1) * np.maximum(dq, 0))
        add += -50.0 * np.maximum(np.abs(dq) - onset, 0.0) * np.sign(dq) * np.diag(kin.M)
        image = kin.Lambda @ kin.J @ kin.M_inv  # the task force of a joint torque
        out = np.zeros(n)
        taken = limit_kernels.normal_neutral_into(q, dq, kin.rec, limits, axis, out)
        f_add, f_sum = image @ add, image @ (add + out)
        assert taken == pytest.approx(axis @ f_add[:3], rel=1e-9, abs=1e-9)
        tol = 1e-4 * max(1.0, np.abs(f_add).max())  # Lambda carries the Cholesky's regularisation
        assert abs(axis @ f_sum[:3]) < tol
        np.testing.assert_allclose(f_sum[:3] - (axis @ f_sum[:3]) * axis, f_add[:3] - (axis @ f_add[:3]) * axis,
                                   atol=tol)
        np.testing.assert_allclose(f_sum[3:], f_add[3:], atol=tol)
    assert abs(taken) > 1.0, "the draws press along the axis (the check can fail)"

def test_disturbance_reference_demand_and_board_kernels_equal_numpy(model, rng):
    kin = Kinematics(model)
    q, dq = _random_state(model, rng)
    kin.update(q, dq)
    n = model.nq
    # disturbance: one low-pass step of M (dq - dq_prev) / dt + nle - applied - J^T w
    watch = DisturbanceWatch(np.full(n, 30.0), 0.02, 0.05)
    dq_prev = dq + rng.normal(0, 0.01, n)
    watch.skip(dq_prev)
    applied, wrench = rng.normal(0, 10, n), rng.normal(0, 5, 6)
    watch.update(kin.M, kin.nle, kin.J, dq, applied, wrench, 0.001)
    raw = kin.M @ ((dq - dq_prev) / 0.001) + kin.nle - applied - kin.J.T @ wrench
    np.testing.assert_allclose(watch.tau_d, raw * (0.001 / 0.021), rtol=1e-10)
    # reference of a board-frame setpoint, time-scaled
    Rb = pin.exp3(rng.normal(0, 1, 3))
    origin = rng.normal(0, 1, 3)
    xy, v, a = rng.normal(size=2), rng.normal(size=2), rng.normal(size=2)
    om, dom = rng.normal(size=3), rng.normal(size=3)
    board = records.new_record(records.BOARD_DTYPE)
    board["origin"], board["R"] = origin, Rb
    ref = Reference()
    kernels.reference_into(board, (xy, v, a, Rb, om, dom), (0.01, 0.2, 0.3), 0.6, ref.rec)
    p, tw, ac = ref.p_m, ref.twist, ref.accel
    np.testing.assert_allclose(p, origin + Rb @ np.r_[xy, 0.01], atol=1e-14)
    np.testing.assert_allclose(tw, np.r_[Rb @ np.r_[v, 0.2], om] * 0.6, atol=1e-14)
    np.testing.assert_allclose(ac, np.r_[Rb @ np.r_[a, 0.3], dom] * 0.36, atol=1e-14)
    # the joint speeds the unscaled reference asks for
    demand = np.zeros(n)
    demand_kernels.joint_demand_into(kin.M_inv, kin.J, kin.Lambda, tw, ac, 0.6, 0.1, demand, np.zeros((4, 7)))
    u, b = tw / 0.6, ac / 0.36
    v = np.zeros(6)
    for k in (slice(0, 3), slice(3, 6)):  # each part along u + 0.1 b, as fast as u speeds up along itself
        w, su = u[k] + 0.1 * b[k], np.linalg.norm(u[k])
        v[k] = w / np.linalg.norm(w) * abs(su + 0.1 * (u[k] @ b[k]) / su)
    A = kin.M_inv @ kin.J.T @ kin.Lambda
    now, ahead = A @ u, A @ v
    np.testing.assert_allclose(demand, np.where(abs(now) > abs(ahead), now, ahead), rtol=1e-9)
    # the pad in the board frame and the normal force
    xyh, vb = np.zeros(3), np.zeros(3)
    f = kernels.tool_in_board(board, kin.rec, wrench, xyh, vb)
    np.testing.assert_allclose(xyh, (kin.p - origin) @ Rb, atol=1e-14)
    np.testing.assert_allclose(vb, Rb.T @ kin.twist[:3], atol=1e-14)
    assert f == pytest.approx(wrench[:3] @ Rb[:, 2], abs=1e-14)


def test_the_speed_demand_looks_ahead_along_the_motion_not_around_a_curve(model):
    """The override's look-ahead: a straight acceleration raises the predicted speed by ``lookahead a``; a circle
    at constant speed (acceleration across the motion) keeps its speed, only turned ahead (a linear extrapolation
    would over-state it by sqrt(1 + (lookahead Omega)^2), 1.4x at 10 rad/s); from rest it is ``lookahead a``; a
    braking motion asks for its speed now, one braking through zero for its speed back; never less than now."""
    kin = Kinematics(model)
    kin.update(np.array([0.3, 0.7, -0.2, -1.5, 0.4, 0.9, 0.1]), np.zeros(model.nq))
    A = kin.M_inv @ kin.J.T @ kin.Lambda

    def demand(twist, accel):
        out = np.zeros(model.nq)
        demand_kernels.joint_demand_into(kin.M_inv, kin.J, kin.Lambda, np.asarray(twist, float),
                                         np.asarray(accel, float), 1.0, 0.1, out, np.zeros((4, 7)))
        return out

    def larger(*vs):  # per joint, the demand of the largest magnitude
        d = np.array([A @ np.asarray(v, float) for v in vs])
        return d[np.argmax(abs(d), axis=0), np.arange(d.shape[1])]

    np.testing.assert_allclose(demand([0.3, 0, 0, 0, 0, 0], [2.0, 0, 0, 0, 0, 0]), A @ [0.5, 0, 0, 0, 0, 0],
                               rtol=1e-9)
    turned = np.r_[0.3, 0.3 * 0.1 * 10, 0, 0, 0, 0] / np.sqrt(2)  # r = 3 cm at 10 rad/s: speed kept, turned ahead
    turning = demand([0.3, 0, 0, 0, 0, 0], [0, 3.0, 0, 0, 0, 0])
    np.testing.assert_allclose(turning, larger([0.3, 0, 0, 0, 0, 0], turned), rtol=1e-9)
    assert np.abs(turning).max() < np.abs(A @ [0.3, 0.3, 0, 0, 0, 0]).max()  # below the linear extrapolation
    np.testing.assert_allclose(demand(np.zeros(6), [0, 0, 0, 0, 0, 4.0]), A @ [0, 0, 0, 0, 0, 0.4], rtol=1e-9)
    # braking: the speed now; braking through zero: back the other way, as fast as it will be then
    np.testing.assert_allclose(demand([0, 0.3, 0, 0, 0, 0], [0, -2.0, 0, 0, 0, 0]), A @ [0, 0.3, 0, 0, 0, 0],
                               rtol=1e-9)
    np.testing.assert_allclose(demand([0, 0.05, 0, 0, 0, 0], [0, -1.5, 0, 0, 0, 0]),
                               larger([0, 0.05, 0, 0, 0, 0], [0, -0.1, 0, 0, 0, 0]), rtol=1e-9)
    # never less than what the reference asks for now, whatever the prediction's direction
    u, b = np.r_[0.05, 0, 0, 0, 0, 0], np.r_[-0.5, 0.05, 0, 0, 0, 0]
    assert np.all(np.abs(demand(u, b)) >= np.abs(A @ u) - 1e-12)


def test_no_kernel_compiles_inside_a_tick():
    """A controller compiles (or loads) every kernel it uses when it is made: a closed-loop approach, contact and
    wiping against the simulator then adds no compiled signature (a new one would stall a tick for seconds)."""
    script = textwrap.dedent("""
        import numpy as np
        from numba.core.registry import CPUDispatcher
        import controller.control.kernels as K, controller.motion as motion
        import controller.control.demand_kernels as DK, controller.control.limit_kernels as LK
        from controller.core import ControllerCore
        from controller.executor_types import BoardPose
        from controller.tick_io import LastCommand, TickInput, TickOutput
        from lampskit.core.planner_types import Stain
        from controller.params import ControllerParams
        from lampskit.learn.learn import bundled_skill
        from sim.core import SimCore
        from sim.params import SimParams

        def signatures():
            found = {}
            for mod in (K, DK, LK, motion):
                for name, obj in vars(mod).items():
                    if isinstance(obj, CPUDispatcher):
                        found[f"{mod.__name__}.{name}"] = len(obj.signatures)
            return found

        sim = SimCore(SimParams.from_table({"camera": {"enabled": False}}))
        core = ControllerCore(ControllerParams.from_table({"trace_ticks": 100, "executor": {"survey_s": 0.0}}),
                              bundled_skill())
        inp, out = TickInput.zeros(7), TickOutput.zeros(7)
        before = signatures()
        phases = set()
        for n in range(8000):  # the first touch creeps from 35 mm: WIPE comes after 4 s
            if n % 100 == 0:
                board = BoardPose.from_transform(sim.board.T_board_to_world, sim.board.size_m)
                core.executor.set_stains(board, [Stain(s.id, np.array(s.centre_m), s.size_m, kappa=False)
                                                 for s in sim.dirt.stains])
            o = sim.out
            inp.set_state(o.q, o.dq, o.wrench, 0.001, False)
            inp.set_last(LastCommand.UNKNOWN if n == 0 else LastCommand.APPLIED, None if n == 0 else tau_prev)
            core.tick(inp, out)
            tau_prev = out.tau_nm.copy()
            phases.add(str(core.executor.phase))
            sim.step(tau_prev)
        sim.close()
        after = signatures()
        print(sorted(phases))
        assert after == before, {k: (before.get(k), v) for k, v in after.items() if before.get(k) != v}
        assert any("WIPE" in p for p in phases), phases
    """)
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-4000:]
