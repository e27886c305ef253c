"""Learning from robot recordings: a known pad path written to rosbag2 folders (sqlite3, MCAP), a bare MCAP file
and the cell's own recording.mcap learns the same skill as the CSV of that path; every refusal names its cause.

The known path: a synthetic demonstration (:func:`~lampskit.learn.synth.synthesize_demo`) moved onto the sim's
wall board, turned into joints by Pinocchio IK; the CSV holds the forward kinematics of those joints (so the
bag and the CSV hold the same path, to float precision). Tolerances: pad path 1 um and sample times 1 ns (the
bag holds the same floats; the CSV prints 9 significant digits); the MPs: the same segments, frequency and
number of cycles to 1e-6 (relative), anchor, amplitude, template and displacements to 1 um, durations to 1 us, basis
weights to 1e-5 of the largest weight (they amplify the CSV's rounding: 4e-7 of it seen).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from arm.robot_model import RobotModel
from interfaces.transforms import tool_rotation_on_board
from lampskit.core.rotations import quat_wxyz_from_matrix
from lampskit.errors import DemoError
from lampskit.learn import bag_maths, bags, demo_io
from lampskit.learn.demo import Demonstration
from lampskit.learn.learn import learn_skill
from lampskit.learn.synth import synthesize_demo
from launch.learn import described_arm
from robot.lbr.msgs import LBR_STATE_MSG

#: The sim's wall board (sim/board.py "wall"): board axes in the world and its origin [m].
R_BOARD = np.column_stack([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])
ORIGIN_BOARD = np.array([0.68, 0.4, 0.25])
JOINTS = [f"lbr_A{i}" for i in range(1, 8)]
#: A static transform above the robot base in the TF tree (base 1 m off the world origin, turned 90 deg).
WORLD_FROM_BASE = (np.array([1.0, 0.5, 0.0]), np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))


@pytest.fixture(scope="module")
def known():
    """Times [ns], joints (T, 7), flange poses, the pad path (Demonstration) and the CSV's skill."""
    s = synthesize_demo(2, seed=3)
    T = s.T_board_to_world
    board = (s.demo.position_m - T[:3, 3]) @ T[:3, :3]
    board[:, :2] += np.array([0.4, 0.3]) - (board[:, :2].min(0) + board[:, :2].max(0)) / 2
    world = board @ R_BOARD.T + ORIGIN_BOARD
    model, R_tool = RobotModel(), tool_rotation_on_board(R_BOARD)
    q = np.array([0.0, 0.6, 0.0, -1.4, 0.0, 0.8, 0.0])
    joints = []
    for p in world:
        q = model.solve_ik(p, R_tool, q)
        joints.append(q)
    joints = np.array(joints)
    arm = described_arm()
    p_flange, R_flange = arm.flange_poses(joints)
    pad = bag_maths.pad_from_frame(p_flange, R_flange, np.array(arm.tool_offset_m))
    t_ns = np.round(s.demo.t_s * 1e9).astype(np.int64) + 1_700_000_000 * 10**9
    demo = Demonstration((t_ns - t_ns[0]) * 1e-9, pad, np.array([quat_wxyz_from_matrix(r) for r in R_flange]))
    return {"t_ns": t_ns, "q": joints, "p_flange": p_flange, "R_flange": R_flange, "demo": demo, "arm": arm}


@pytest.fixture(scope="module")
def csv_skill(known, tmp_path_factory):
    path = demo_io.write_demo_csv(tmp_path_factory.mktemp("csv") / "path.csv", known["demo"])
    skill, _ = learn_skill(demo_io.read_demo(path))
    return skill


# ------------------------------------------------------------------------------------------ writing recordings


def _store():
    store = get_typestore(Stores.ROS2_HUMBLE)
    store.register(get_types_from_msg(LBR_STATE_MSG, bags.LBR_STATE))
    return store


def _messages(known, store, *, names=JOINTS, drop=slice(0, 0)):
    """(topic, type, log time [ns], message) of every topic, time ordered."""
    Time, Header = store.types["builtin_interfaces/msg/Time"], store.types["std_msgs/msg/Header"]
    geo = {k: store.types[f"geometry_msgs/msg/{k}"] for k in ("Point", "Quaternion", "Pose", "PoseStamped",
                                                              "Vector3", "Transform", "TransformStamped")}
    State, Joint = store.types[bags.LBR_STATE], store.types[bags.JOINT_STATE]
    TFMessage = store.types[bags.TF]
    keep = np.ones(len(known["t_ns"]), bool)
    keep[drop] = False
    pad = known["demo"].position_m

    def header(t, frame):
        return Header(stamp=Time(sec=int(t // 10**9), nanosec=int(t % 10**9)), frame_id=frame)

    def quat(R):
        w, x, y, z = quat_wxyz_from_matrix(R)
        return geo["Quaternion"](x=x, y=y, z=z, w=w)

    def tf(t, parent, child, p, R):
        return geo["TransformStamped"](header=header(t, parent), child_frame_id=child,
                                       transform=geo["Transform"](translation=geo["Vector3"](*p), rotation=quat(R)))

    p0, R0 = WORLD_FROM_BASE
    out = [("/tf_static", bags.TF, int(known["t_ns"][0]) - 10**6,
            TFMessage(transforms=[tf(known["t_ns"][0], "world", "lbr_link_0", p0, R0)]))]
    order = [3, 0, 6, 1, 5, 2, 4]  # JointState in another order, with a gripper's joint among them
    for k in np.flatnonzero(keep):
        t, q = int(known["t_ns"][k]), known["q"][k]
        zeros = np.zeros(7)
        out.append(("/lbr/state", bags.LBR_STATE, t, State(
            sample_time=0.001, session_state=4, connection_quality=3, safety_state=0, operation_mode=0, drive_state=2,
            client_command_mode=3, overlay_type=0, control_mode=2, time_stamp_sec=t // 10**9,
            time_stamp_nano_sec=t % 10**9, measured_joint_position=q.copy(), commanded_joint_position=q.copy(),
            measured_torque=zeros, commanded_torque=zeros, external_torque=zeros, ipo_joint_position=q.copy(),
            tracking_performance=1.0)))
        out.append(("/lbr/joint_states", bags.JOINT_STATE, t, Joint(
            header=header(t, ""), name=[names[i] for i in order] + ["gripper_finger"],
            position=np.r_[q[order], 0.01], velocity=np.zeros(0), effort=np.zeros(0))))
        out.append(("/pad_pose", bags.POSE_STAMPED, t, geo["PoseStamped"](
            header=header(t, "lbr_link_0"), pose=geo["Pose"](position=geo["Point"](*pad[k]),
                                                             orientation=quat(known["R_flange"][k])))))
        out.append(("/tf", bags.TF, t, TFMessage(transforms=[
            tf(t, "lbr_link_0", "lbr_link_ee", known["p_flange"][k], known["R_flange"][k])])))
    return out


def write_rosbag(path, known, storage: str, **kw):
    """A rosbag2 folder (``sqlite3`` or ``mcap`` storage) or, for ``storage="file"``, a bare ROS 2 MCAP file."""
    store = _store()
    msgs = _messages(known, store, **kw)
    if storage == "file":
        from mcap.writer import Writer as McapWriter

        with open(path, "wb") as f:
            w = McapWriter(f)
            w.start(profile="ros2", library="test")
            channels = {}
            for topic, typ, t, msg in msgs:
                if topic not in channels:
                    schema = w.register_schema(name=typ, encoding="ros2msg",
                                               data=store.generate_msgdef(typ, ros_version=2)[0].encode())
                    channels[topic] = w.register_channel(topic=topic, message_encoding="cdr", schema_id=schema)
                w.add_message(channels[topic], log_time=t, publish_time=t, data=bytes(store.serialize_cdr(msg, typ)))
            w.finish()
        return path
    plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
    with Writer(path, version=9, storage_plugin=plugin) as w:
        conns = {}
        for topic, typ, t, msg in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typ, typestore=store)
            w.write(conns[topic], t, store.serialize_cdr(msg, typ))
    return path


@pytest.fixture(scope="module")
def recordings(known, tmp_path_factory):
    d = tmp_path_factory.mktemp("bags")
    return {"sqlite3": write_rosbag(d / "sqlite3_bag", known, "sqlite3"),
            "mcap": write_rosbag(d / "mcap_bag", known, "mcap"),
            "file": write_rosbag(d / "demo.mcap", known, "file")}


# ------------------------------------------------------------------------------------------ the same skill

KINDS = {
    "LBRState": bags.BagOptions(),  # the default: the one LBRState topic
    "JointState": bags.BagOptions(topic="/lbr/joint_states"),
    "PoseStamped": bags.BagOptions(topic="/pad_pose"),
    "TF": bags.BagOptions(frame="lbr_link_ee", base_frame="lbr_link_0", tool_offset_m=(0.0, 0.0, 0.035)),
}


def assert_same_skill(a, b):
    assert [e.segment for e in a.periodic] == [e.segment for e in b.periodic]
    assert [e.segment for e in a.transitional] == [e.segment for e in b.transitional]
    for x, y in zip(a.periodic, b.periodic):
        np.testing.assert_allclose(x.mp.omega_rad_s, y.mp.omega_rad_s, rtol=1e-6)
        np.testing.assert_allclose(x.mp.amplitude_m, y.mp.amplitude_m, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(x.mp.anchor_m, y.mp.anchor_m, atol=1e-6)
        np.testing.assert_allclose(x.mp.template_m, y.mp.template_m, atol=1e-6)
        # the basis weights amplify the CSV's 9 printed digits: 1e-5 of the largest weight
        np.testing.assert_allclose(x.mp.weights, y.mp.weights, atol=1e-5 * np.abs(y.mp.weights).max())
        np.testing.assert_allclose(x.n_cycles, y.n_cycles, rtol=1e-6)
    for x, y in zip(a.transitional, b.transitional):
        np.testing.assert_allclose(x.mp.demo_duration_s, y.mp.demo_duration_s, atol=1e-6)
        np.testing.assert_allclose(x.mp.demo_displacement_m, y.mp.demo_displacement_m, atol=1e-6)
        np.testing.assert_allclose(x.mp.weights, y.mp.weights, atol=1e-5 * np.abs(y.mp.weights).max())


@pytest.mark.parametrize("storage", ["sqlite3", "mcap", "file"])
@pytest.mark.parametrize("kind", list(KINDS))
def test_a_recording_learns_the_skill_of_the_csv_of_its_path(recordings, known, csv_skill, storage, kind):
    demo = bags.read_recording_demo(recordings[storage], known["arm"], KINDS[kind])
    np.testing.assert_allclose(demo.t_s, known["demo"].t_s, atol=1e-9)
    np.testing.assert_allclose(demo.position_m, known["demo"].position_m, atol=1e-6)
    assert len(csv_skill.periodic) == 2 and len(csv_skill.transitional) >= 2
    assert_same_skill(learn_skill(demo)[0], csv_skill)


def test_the_cells_own_recording_learns_the_same_skill(known, csv_skill, tmp_path):
    from interfaces.keys import Keys
    from interfaces.messages import Capabilities, RobotState
    from launch.record import McapSink

    keys = Keys()
    sink = McapSink(tmp_path / "recording.mcap")
    caps = Capabilities(gravity_compensated=True, torque_limits_nm=[300.0] * 7)
    for k, (t, q) in enumerate(zip(known["t_ns"], known["q"])):
        sink.write(keys.robot_state, RobotState(seq=k, stamp_ns=k, q_rad=q.tolist(), dq_rad_s=[0.0] * 7,
                                                tau_nm=[0.0] * 7, wrench_world=[0.0] * 6, capabilities=caps,
                                                robot_time_ns=int(t - known["t_ns"][0]) + 10**6), int(t))
    sink.finish()
    demo = bags.read_recording_demo(tmp_path / "recording.mcap", known["arm"])
    np.testing.assert_allclose(demo.position_m, known["demo"].position_m, atol=1e-6)
    assert_same_skill(learn_skill(demo)[0], csv_skill)


def test_tf_without_a_base_frame_gives_the_frame_in_its_trees_root(recordings, known):
    demo = bags.read_recording_demo(recordings["mcap"], known["arm"], bags.BagOptions(frame="lbr_link_ee"))
    p0, R0 = WORLD_FROM_BASE
    np.testing.assert_allclose(demo.position_m, known["p_flange"] @ R0.T + p0, atol=1e-6)


def test_a_time_window_cuts_the_path(recordings, known):
    demo = bags.read_recording_demo(recordings["sqlite3"], known["arm"], bags.BagOptions(start_s=2.0, end_s=6.0))
    inside = (known["demo"].t_s >= 2.0) & (known["demo"].t_s <= 6.0)
    np.testing.assert_allclose(demo.position_m, known["demo"].position_m[inside], atol=1e-6)


# ------------------------------------------------------------------------------------------ refusals


@pytest.fixture(scope="module")
def odd_bags(known, tmp_path_factory):
    d = tmp_path_factory.mktemp("odd")
    k = int(np.searchsorted(known["demo"].t_s, 5.0))
    return {"gap": write_rosbag(d / "gap", known, "mcap", drop=slice(k, k + 30)),
            "panda": write_rosbag(d / "panda.mcap", known, "file", names=[f"panda_joint{i}" for i in range(1, 8)])}


@pytest.mark.parametrize("case, options, match", [
    ("missing topic", bags.BagOptions(topic="/nope"),
     r"no topic '/nope' in it; it has /lbr/joint_states \(sensor_msgs/msg/JointState, \d+\), /lbr/state \("),
    ("tf without a frame", bags.BagOptions(topic="/tf"), "carries transforms: name the frame to learn with --frame"),
    ("unknown frame", bags.BagOptions(frame="eraser"),
     r"no transform to the frame 'eraser'; the transforms' child frames are \['lbr_link_0', 'lbr_link_ee'\]"),
    ("base not above", bags.BagOptions(frame="lbr_link_ee", base_frame="camera"),
     r"the base frame 'camera' is not above 'lbr_link_ee': its chain is lbr_link_ee <- lbr_link_0 <- world"),
    ("empty window", bags.BagOptions(start_s=100.0),
     r"no sample in the time range 100 s..end; the topic spans 0.000..11.\d+ s from its first sample"),
])
def test_a_recording_is_refused_naming_what_it_holds(recordings, known, case, options, match):
    with pytest.raises(DemoError, match=match):
        bags.read_recording_demo(recordings["sqlite3"], known["arm"], options)


def test_a_gap_is_refused_naming_its_time_and_a_window_without_it_is_learned(odd_bags, known):
    with pytest.raises(DemoError, match=r"/lbr/state: a gap of 0\.\d+ s in the samples at t=4\.9\d+ s "
                                        r"\(the limit is 0\.050 s"):
        bags.read_recording_demo(odd_bags["gap"], known["arm"])
    demo = bags.read_recording_demo(odd_bags["gap"], known["arm"], bags.BagOptions(end_s=4.9))
    assert demo.t_s[-1] <= 4.9
    demo = bags.read_recording_demo(odd_bags["gap"], known["arm"], bags.BagOptions(max_gap_s=1.0))
    assert demo.n_samples == known["demo"].n_samples - 30


def test_another_robots_joint_names_are_refused(odd_bags, known):
    with pytest.raises(DemoError, match=r"/lbr/joint_states: joint names \['panda_joint4', 'panda_joint1', .*"
                                        r"'gripper_finger'\] are not the arm's 7 joints \(A1..A7, "):
        bags.read_recording_demo(odd_bags["panda"], known["arm"], bags.BagOptions(topic="/lbr/joint_states"))


def test_a_recording_without_a_state_topic_is_refused(tmp_path, known):
    store = get_typestore(Stores.ROS2_HUMBLE)
    String = store.types["std_msgs/msg/String"]
    with Writer(tmp_path / "chat", version=9, storage_plugin=StoragePlugin.SQLITE3) as w:
        c = w.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        w.write(c, 1, store.serialize_cdr(String(data="hi"), "std_msgs/msg/String"))
    with pytest.raises(DemoError, match=r"no robot state, joint state or pose topic in it \(it has /chatter "
                                        r"\(std_msgs/msg/String, 1\)\); give --topic"):
        bags.read_recording_demo(tmp_path / "chat", known["arm"])
    with pytest.raises(DemoError, match=r"/chatter carries std_msgs/msg/String; readable: lbr_fri_idl/msg/LBRState"):
        bags.read_recording_demo(tmp_path / "chat", known["arm"], bags.BagOptions(topic="/chatter"))
    (tmp_path / "bad.mcap").write_bytes(b"not an mcap")
    with pytest.raises(DemoError, match="not a readable MCAP file"):
        bags.read_recording_demo(tmp_path / "bad.mcap", known["arm"])


# ------------------------------------------------------------------------------------------ the maths


def test_joint_names_of_the_stack_and_of_the_description_are_the_iiwas():
    from launch.learn import iiwa_joint_index

    assert [iiwa_joint_index(n) for n in ("A1", "lbr_A7", "my_arm_A3", "iiwa_joint_5")] == [0, 6, 2, 4]
    assert [iiwa_joint_index(n) for n in ("panda_joint1", "A8", "A", "joint_a1")] == [None] * 4


def test_a_frame_chain_composes_static_and_moving_links():
    rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    links = {"base": bag_maths.FrameLink("world", "base", None, np.array([[1.0, 0, 0]]), rz[None]),
             "arm": bag_maths.FrameLink("base", "arm", np.array([10, 20]), np.array([[0, 0, 1.0], [0, 0, 2.0]]),
                                        np.tile(np.eye(3), (2, 1, 1))),
             "tip": bag_maths.FrameLink("arm", "tip", np.array([5, 15, 25]), np.array([[1.0, 0, 0]] * 3),
                                        np.tile(rz, (3, 1, 1)))}
    t, p, R = bag_maths.compose_chain(bag_maths.chain_to("tip", links, None))
    np.testing.assert_array_equal(t, [15, 25])  # the tip's stamp 5 is before the arm was first seen
    np.testing.assert_allclose(p, [[1.0, 1.0, 1.0], [1.0, 1.0, 2.0]])  # world <- base: 90 deg about z, +1 in x
    np.testing.assert_allclose(R, np.tile(rz @ rz, (2, 1, 1)))


def test_thinning_keeps_every_kth_sample_down_to_the_rate():
    t = np.arange(1001) / 1000.0
    assert len(bag_maths.thin(t)) == 251  # 1 kHz -> every 4th: 250 Hz
    assert len(bag_maths.thin(t[::10])) == 101  # 100 Hz stays


# ------------------------------------------------------------------------------------------ lamps learn


def test_lamps_learn_reads_a_bag_with_its_options(recordings, csv_skill, tmp_path, capsys):
    from lampskit.core.skill import load_skill
    from runtime.cli import main

    out = tmp_path / "skill.json"
    assert main(["learn", str(recordings["sqlite3"]), "--topic", "/tf", "--frame", "lbr_link_ee",
                 "--base-frame", "lbr_link_0", "--tool-offset", "0,0,0.035", "-o", str(out)]) == 0
    assert_same_skill(load_skill(out), csv_skill)
    assert "skill: 2 periodic MP(s)" in capsys.readouterr().out


@pytest.mark.parametrize("args, match", [
    (["--topic", "/nope"], r"^lamps learn: error: \S+sqlite3_bag: no topic '/nope' in it; it has /lbr/joint_states "),
    (["--tool-offset", "0,0"], r"^lamps learn: error: argument --tool-offset: '0,0' is not X,Y,Z in metres"),
])
def test_lamps_learn_refuses_in_one_line_without_output(recordings, tmp_path, capsys, args, match):
    """The reason is the last line (argparse prints its usage above a bad option's)."""
    from runtime.cli import main

    out = tmp_path / "skill.json"
    try:
        code = main(["learn", str(recordings["sqlite3"]), "-o", str(out), *args])
    except SystemExit as exc:  # argparse's exit on a bad option
        code = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and not out.exists()
    assert re.search(match, err[-1]), err


def test_the_learning_library_alone_refuses_a_recording_it_has_no_arm_for(recordings, tmp_path, capsys):
    """lampskit knows no robot: without the arm the cell's ``lamps learn`` hands it, a recording is refused."""
    from lampskit.cli import learn_main

    out = tmp_path / "skill.json"
    assert learn_main([str(recordings["sqlite3"]), "-o", str(out)]) == 1 and not out.exists()
    assert "a robot recording is read with an arm's description, and none was given" in capsys.readouterr().err


def test_recording_options_on_a_csv_are_refused(tmp_path, known, capsys):
    from runtime.cli import main

    csv = demo_io.write_demo_csv(tmp_path / "d.csv", known["demo"])
    assert main(["learn", str(csv), "-o", str(tmp_path / "s.json"), "--frame", "x", "--start", "1"]) == 1
    assert "--frame, --start: only for robot recordings" in capsys.readouterr().err


@pytest.mark.parametrize("fri", [1, 2])
def test_an_lbr_state_without_its_definition_is_decoded_in_the_stacks_layout(known, tmp_path, fri):
    """A bag that embeds no definition (sqlite3 before ROS 2 Iron): the FRI 1 layout, else the FRI 2 one."""
    from robot.lbr.msgs import LBR_STATE_MSG_FRI2

    store = get_typestore(Stores.ROS2_HUMBLE)
    store.register(get_types_from_msg(LBR_STATE_MSG if fri == 1 else LBR_STATE_MSG_FRI2, bags.LBR_STATE))
    State, zeros = store.types[bags.LBR_STATE], np.zeros(7)
    with Writer(tmp_path / "humble", version=8, storage_plugin=StoragePlugin.SQLITE3) as w:
        c = w.add_connection("/lbr/state", bags.LBR_STATE, msgdef="", rihs01="RIHS01_unknown")
        for t, q in zip(known["t_ns"], known["q"]):
            fields = dict(sample_time=0.001, session_state=4, connection_quality=3, safety_state=0, operation_mode=0,
                          drive_state=2, client_command_mode=3, overlay_type=0, control_mode=2,
                          time_stamp_sec=int(t) // 10**9, time_stamp_nano_sec=int(t) % 10**9,
                          measured_joint_position=q.copy(), measured_torque=zeros, commanded_torque=zeros,
                          external_torque=zeros, ipo_joint_position=q.copy(), tracking_performance=1.0)
            if fri == 1:
                fields["commanded_joint_position"] = q.copy()
            w.write(c, int(t), store.serialize_cdr(State(**fields), bags.LBR_STATE))
    demo = bags.read_recording_demo(tmp_path / "humble", known["arm"])
    np.testing.assert_allclose(demo.position_m, known["demo"].position_m, atol=1e-6)
