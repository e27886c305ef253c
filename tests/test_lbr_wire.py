"""The adapter's decoder against bytes made from the stack's own message texts (tests/fixtures/lbr, NOTICE.md).

The fixtures were written by rosbags from lbr_fri_idl's ``LBRState.msg`` of
its ``fri-1`` and ``fri-2`` branches and a JointState with the humble
branch's joint names, independently of :mod:`robot.lbr.msgs`.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from robot.lbr import msgs
from robot.lbr.msgs import LbrWireError, decode_joint_names, decode_state, encode_state, stack_joint_names, state_layout
from robot.lbr.params import LbrParams

HERE = Path(__file__).resolve().parent / "fixtures" / "lbr"


def _fixture_values():
    spec = importlib.util.spec_from_file_location("make_fixtures", HERE / "make_fixtures.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("major", [1, 2])
def test_a_state_of_each_fri_layout_decodes_field_by_field(major):
    fx = _fixture_values()
    raw = (HERE / f"lbr_state_fri{major}.cdr").read_bytes()
    assert state_layout(raw) == major and len(raw) == msgs.state_size(major)
    st = decode_state(raw, major)
    assert st.sample_time_s == 0.002 and st.session_state == 4 and st.client_command_mode == 3
    assert st.control_mode == 2 and st.drive_state == 2 and st.safety_state == 0 and st.operation_mode == 0
    assert st.stamp_ns == 1700000123 * 10**9 + 456000000
    np.testing.assert_array_equal(st.q_rad, fx.Q)
    np.testing.assert_array_equal(st.tau_measured_nm, fx.ARRAYS["measured_torque"])
    np.testing.assert_array_equal(st.tau_external_nm, fx.ARRAYS["external_torque"])
    if major == 1:
        np.testing.assert_array_equal(st.q_commanded_rad, fx.COMMANDED)
    else:
        assert st.q_commanded_rad is None  # FRI 2 has no commanded joint position


@pytest.mark.parametrize("major", [1, 2])
def test_our_encoder_writes_the_fixture_bytes_exactly(major):
    fx = _fixture_values()
    a = fx.ARRAYS
    st = msgs.LbrState(0.002, 4, 0, 0, 2, 3, 2, 1700000123 * 10**9 + 456000000, fx.Q, a["measured_torque"],
                       a["external_torque"], fx.COMMANDED if major == 1 else None)
    raw = encode_state(st, connection_quality=3, overlay_type=1, commanded_torque_nm=a["commanded_torque"],
                       fri_major=major, ipo_joint_position_rad=a["ipo_joint_position"])
    assert raw == (HERE / f"lbr_state_fri{major}.cdr").read_bytes()


def test_the_other_layout_is_named_with_the_setting_to_change():
    fri2 = (HERE / "lbr_state_fri2.cdr").read_bytes()
    with pytest.raises(LbrWireError, match=r"an FRI 2 LBRState \(316 bytes\), but the adapter expects FRI 1 "
                                           r"\(372 bytes\): set \[lbr\] fri_major = 2"):
        decode_state(fri2, 1)
    with pytest.raises(LbrWireError, match=r"set \[lbr\] fri_major = 1"):
        decode_state((HERE / "lbr_state_fri1.cdr").read_bytes(), 2)
    with pytest.raises(LbrWireError, match="not a valid CDR"):
        decode_state(fri2[:200], 2)


def test_humble_joint_names_are_the_branchs():
    names = decode_joint_names((HERE / "joint_state_humble.cdr").read_bytes())
    assert names == stack_joint_names("humble") == tuple(f"A{i}" for i in range(1, 8))
    assert LbrParams(branch="humble").joint_names == names
    assert LbrParams(branch="rolling").joint_names == tuple(f"lbr_A{i}" for i in range(1, 8))
    assert LbrParams(branch="jazzy", namespace="arm2").joint_names[0] == "arm2_A1"


def test_the_torque_command_text_is_the_one_we_encode():
    text = (HERE / "LBRTorqueCommand.msg").read_text()
    fields = [line.strip() for line in text.splitlines() if line.strip() and not line.startswith("#")]
    ours = [line.strip() for line in msgs.LBR_TORQUE_COMMAND_MSG.splitlines() if line.strip()]
    assert fields == ours


def test_robot_check_names_the_layout_and_warns_of_open_loop(capsys, monkeypatch):
    from robot import cli

    assert cli.main(["--check", "--backend", "lbr"]) == 0
    out = capsys.readouterr().out
    assert "rolling joint names, FRI 1 states" in out and "arming will be refused" in out
    monkeypatch.setenv("LAMPS__LBR__OPEN_LOOP", "false")
    monkeypatch.setenv("LAMPS__LBR__FRI_MAJOR", "2")
    monkeypatch.setenv("LAMPS__LBR__BRANCH", "humble")
    assert cli.main(["--check", "--backend", "lbr"]) == 0
    out = capsys.readouterr().out
    assert "humble joint names, FRI 2 states" in out and "arming will be refused" not in out
