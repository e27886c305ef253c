"""The simulated arm in the physics client: apply torques or brake, step, read back what a real arm reports.

:class:`SimRobot` is the sim's hardware: ``write`` torques (or ``brake``),
``step`` the physics, ``read`` joint state, applied torques and the
eraser's contact with the board. The written torques drive joints with
rotor inertia and friction (:mod:`.drive`, figures in
:mod:`arm.joint_dynamics`). Readouts land in one preallocated
:class:`Readout`, so a step allocates little.

The contact wrench is what the arm felt, from its own motion: PyBullet
steps ``M (dq' - dq) / dt = tau_pb - h + J^T f`` (semi-implicit Euler), so

    J^T f = M (dq' - dq) / dt + h - tau_pb

with ``M``, ``h`` at the step's start (the drive computes them anyway) and
``tau_pb`` the torques it was given, ``f`` (6,) at the pad centre by least
squares (``J`` is 6 x 7). The contact points' own friction cannot be taken
for it: with a heavy tool merged into the eraser link (``[sim.plant]
tool_mass_kg``) PyBullet reports each point's lateral friction against
the pad's sliding (a 1.4 kg tool: -3.3 N along a pad moving at -0.023 m/s,
where the arm's motion says +3.4 N), and a force sensor that reads the
friction backwards is a torque the controller cannot explain. The points
still say whether the pad touches (and whether an arm link does) and give
the normal force the wiping and the sim's truth use (that one they report
right); a
braked step (PyBullet's velocity motors, torques unknown) takes their
wrench as reported.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pybullet as pb

from arm.joint_dynamics import JointDynamics

from .drive import drive_torque_into, drives_record
from .plant import tool_gravity_torque
from .step_dynamics import StepDynamics
from .world import GRAVITY_M_S2, World


@dataclass
class Readout:
    """What the arm reports after a step (world frame, SI units).

    q, dq, tau : (7,) joint positions [rad], velocities [rad/s], applied torques [Nm].
    wrench : (6,) force [N] and torque about the TCP [Nm] the board exerts on the eraser (its links only).
    normal_force_n : that force along the board normal (pressing) [N].
    tcp_p, tcp_v, tcp_w : (3,) pad centre position [m], velocity [m/s], angular velocity [rad/s].
    tcp_R : (3, 3) pad orientation. arm_contact : a link other than the eraser touches the board.
    """

    q: np.ndarray = field(default_factory=lambda: np.zeros(7))
    dq: np.ndarray = field(default_factory=lambda: np.zeros(7))
    tau: np.ndarray = field(default_factory=lambda: np.zeros(7))
    wrench: np.ndarray = field(default_factory=lambda: np.zeros(6))
    normal_force_n: float = 0.0
    tcp_p: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tcp_R: np.ndarray = field(default_factory=lambda: np.eye(3))
    tcp_v: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tcp_w: np.ndarray = field(default_factory=lambda: np.zeros(3))
    arm_contact: bool = False


#: How long [s] a brake takes to stop the arm: each joint's speed is ramped from what it was to zero over this
#: time, all joints together (the arm stays on its path, as a robot's path-maintaining stop does), then held at zero.
#: A brake that locks every joint within a step stopped a pad wiping at 0.2 m/s so hard that it pressed the board
#: at 36 N for that step (wiping at 10 N) in a real-time fault cell.
BRAKE_STOP_S = 0.02


class BrakeRamp:
    """A brake's stop: each joint's speed ramped from what it was when the brake engaged to zero over
    :data:`BRAKE_STOP_S`, all joints together.

    steps : the ramp's length [physics steps]; k : the steps of it done (``steps``: the arm stands; ``steps + 1``:
    it has stood for a step, so the brakes' torque is what holds it, no longer what stops it); dq_start : (n,) the
    joint speeds the brake began at [rad/s].
    """

    __slots__ = ("steps", "k", "dq_start")

    def __init__(self, n: int, dt_s: float) -> None:
        self.steps = max(int(round(BRAKE_STOP_S / dt_s)), 1)
        self.k = self.steps + 1
        self.dq_start = np.zeros(n)

    def start(self, dq: np.ndarray) -> None:
        """Begin the ramp from the joint speeds ``dq`` (n,) [rad/s]."""
        self.dq_start[:] = dq
        self.k = 0

    def next_speeds(self) -> list[float] | None:
        """The joints' target speeds [rad/s] for the next step; None once the ramp is done."""
        if self.k >= self.steps:
            self.k = self.steps + 1
            return None
        self.k += 1
        left = 1.0 - self.k / self.steps
        return (self.dq_start * left).tolist()


class SimRobot:
    """Torque-controlled arm with brakes, in a built :class:`~sim.world.World`.

    Parameters
    ----------
    tau_max : (7,) joint torque limits [Nm]; the brakes hold up to these (stopping over :data:`BRAKE_STOP_S`).
    board_normal : (3,) outward normal of the board (pressing force is along -normal).
    gravity_compensated : add :meth:`compensation` to every command, like the real iiwa.
    joints : rotor inertia and friction of the drives (default: the cited iiwa figures); the
        simulated arm's own (:func:`sim.plant.plant_joints`), which the controller's model need not share.
    dt_s : physics step [s] (default: the client's).
    load : None when the robot's load data is the tool it carries; else (true tool mass [kg], its centre of
        mass (3,) in the eraser (flange) frame [m], load data mass [kg], load data centre of mass (3,) [m]).
    """

    def __init__(self, world: World, tau_max: np.ndarray, board_normal: np.ndarray,
                 gravity_compensated: bool = False, joints: JointDynamics | None = None,
                 dt_s: float | None = None,
                 load: tuple[float, np.ndarray, float, np.ndarray] | None = None) -> None:
        self.w = world
        self.c = world.client
        self.tau_max = np.asarray(tau_max, float)
        self._tau_min = -self.tau_max
        self.normal = np.asarray(board_normal, float)
        self.gravity_compensated = gravity_compensated
        self.load = load
        self.joints = joints or JointDynamics()
        self._rigid = self.joints.is_rigid
        self.dt_s = float(dt_s if dt_s is not None
                          else pb.getPhysicsEngineParameters(physicsClientId=self.c)["fixedTimeStep"])
        self.braked = False
        self._brake = BrakeRamp(len(world.joints), self.dt_s)
        self.out = Readout()
        #: (6,) a wrench [N, Nm] (world axes, at the pad centre) someone else puts on the tool for the next step
        #: (the operator's hand, :mod:`.hand`); not in the contact wrench the readout reports
        self.external_wrench = np.zeros(6)
        self._joints = list(world.joints)
        n = len(self._joints)
        self._zeros = [0.0] * n
        self._tau_cmd = np.zeros(n)
        self._drives = drives_record(self.joints, self.dt_s)  # the drives' friction and armature, the kernel's scratch
        self._step = StepDynamics(world, self._zeros, self.dt_s)  # the step's start, for the wrench from the motion
        self.read()
        if not self._rigid:
            self._drive_torque()  # compiles (or loads) the kernel now, not in the first step

    def write(self, tau_nm: np.ndarray) -> None:
        """Torques [Nm] (7,) for the next step (already validated and clipped); releases the brakes."""
        if self.braked:
            pb.setJointMotorControlArray(self.w.robot, self._joints, pb.VELOCITY_CONTROL, forces=self._zeros,
                                         physicsClientId=self.c)
            self.braked = False
        tau = np.asarray(tau_nm, float)
        if self.gravity_compensated:
            tau = tau + self.compensation()
        np.maximum(np.minimum(tau, self.tau_max, out=self._tau_cmd), self._tau_min, out=self._tau_cmd)  # np.clip's cost
        st = self._step
        if self._rigid:  # no drive needs M and h: taken only while the pad touched (its first step keeps the points')
            touched = bool(self.out.wrench.any())
            if touched:
                self._start_dynamics()
            st.tau_pb[:] = self._tau_cmd
            applied = st.tau_pb
            st.torques_known = touched
        else:
            applied = self._drive_torque()
            st.torques_known = True
        pb.setJointMotorControlArray(self.w.robot, self._joints, pb.TORQUE_CONTROL, forces=applied.tolist(),
                                     physicsClientId=self.c)

    def _start_dynamics(self) -> None:
        """PyBullet's ``M`` and ``h = C dq + g`` at the step's start (and the pad's Jacobian while it is loaded)."""
        o = self.out
        self._step.take(o.q, o.dq, bool(o.wrench.any() or self.external_wrench.any()))

    def _drive_torque(self) -> np.ndarray:
        """The torques PyBullet must apply so the arm moves as one with armature and friction (:mod:`.drive`)."""
        o, st = self.out, self._step
        self._start_dynamics()
        M = st.M
        h_hat = st.h.copy()
        if st.J is not None:  # the contact of the last step stands for this one's, the hand's is this step's
            h_hat -= st.J.T @ (o.wrench + self.external_wrench)
        ok = drive_torque_into(self._tau_cmd, o.dq, M, h_hat, self._drives, st.tau_pb)
        return st.tau_pb if ok else self._tau_cmd  # (M + Ia is positive definite for any arm PyBullet loads)

    @property
    def stopping(self) -> bool:
        """Whether the brakes are still stopping the arm: their ramp (:data:`BRAKE_STOP_S`) and a step at rest."""
        return self.braked and self._brake.k <= self._brake.steps

    def brake(self) -> None:
        """Engage the brakes for the next step: every joint's speed ramped from what it was when they engaged to
        zero over :data:`BRAKE_STOP_S`, all together, then held at zero, with up to its torque limit."""
        self._step.torques_known = False  # PyBullet's velocity motors: what they apply is not known here
        if not self.braked:
            self.braked = True
            self._brake.start(self.out.dq)
        speeds = self._brake.next_speeds()
        if speeds is not None:
            pb.setJointMotorControlArray(self.w.robot, self._joints, pb.VELOCITY_CONTROL, targetVelocities=speeds,
                                         forces=self.tau_max.tolist(), physicsClientId=self.c)

    def gravity(self) -> np.ndarray:
        """(7,) gravity torques [Nm] at the current joint positions (arm and eraser)."""
        return np.array(pb.calculateInverseDynamics(self.w.robot, self.out.q.tolist(), self._zeros, self._zeros,
                                                    physicsClientId=self.c))

    def compensation(self) -> np.ndarray:
        """(7,) what a gravity-compensated robot adds [Nm]: its own weight by its true model, the tool by its load
        data (:attr:`load`): g(q) + m_load g J_z(c_load)^T - m_tool g J_z(c_tool)^T."""
        g = self.gravity()
        if self.load is not None:
            m_true, c_true, m_load, c_load = self.load
            q, c, robot, link = self.out.q.tolist(), self.c, self.w.robot, self.w.tcp_link
            g += tool_gravity_torque(c, robot, link, q, m_load, c_load, self._zeros, GRAVITY_M_S2)
            g -= tool_gravity_torque(c, robot, link, q, m_true, c_true, self._zeros, GRAVITY_M_S2)
        return g

    def step(self) -> None:
        """One physics step, with :attr:`external_wrench` on the pad (PyBullet clears external forces each step)."""
        f = self.external_wrench
        if f.any():
            pb.applyExternalForce(self.w.robot, self.w.tcp_link, f[:3].tolist(), self.out.tcp_p.tolist(),
                                  pb.WORLD_FRAME, physicsClientId=self.c)
            pb.applyExternalTorque(self.w.robot, self.w.tcp_link, f[3:].tolist(), pb.WORLD_FRAME,
                                   physicsClientId=self.c)
        pb.stepSimulation(physicsClientId=self.c)

    def read(self) -> Readout:
        """Refresh and return :attr:`out`."""
        o, c, robot = self.out, self.c, self.w.robot
        states = pb.getJointStates(robot, self._joints, physicsClientId=c)
        for i, s in enumerate(states):
            o.q[i], o.dq[i] = s[0], s[1]
            o.tau[i] = s[3] if self.braked else self._tau_cmd[i]
        link = pb.getLinkState(robot, self.w.tcp_link, computeLinkVelocity=1, computeForwardKinematics=1,
                               physicsClientId=c)
        o.tcp_p[:] = link[4]
        o.tcp_R[:] = np.array(pb.getMatrixFromQuaternion(link[5])).reshape(3, 3)
        o.tcp_v[:] = link[6]
        o.tcp_w[:] = link[7]
        self._read_contacts()
        return o

    def _read_contacts(self) -> None:
        o = self.out
        o.arm_contact = False
        contacts = pb.getContactPoints(self.w.robot, self.w.board, physicsClientId=self.c)
        px, py, pz = o.tcp_p
        fx = fy = fz = mx = my = mz = 0.0
        for cp in contacts:
            fn, f1, f2 = cp[9], cp[10], cp[12]
            if fn <= 0.0:
                continue  # a point within the contact margin that carries no load
            if cp[3] not in (self.w.eraser_link, self.w.tcp_link):
                o.arm_contact = True  # an arm link leans on the board: flagged, not the eraser's force
                continue
            n, d1, d2 = cp[7], cp[11], cp[13]  # normal on the board, pointing towards the robot
            # PyBullet reports friction as acting on the board (B); the eraser (A) feels the opposite.
            cx, cy, cz = (fn * n[i] - f1 * d1[i] - f2 * d2[i] for i in range(3))
            rx, ry, rz = cp[5][0] - px, cp[5][1] - py, cp[5][2] - pz
            fx, fy, fz = fx + cx, fy + cy, fz + cz
            mx, my, mz = mx + ry * cz - rz * cy, my + rz * cx - rx * cz, mz + rx * cy - ry * cx
        o.wrench[:] = (fx, fy, fz, mx, my, mz)
        if fx or fy or fz:  # the wrench the step's motion says the pad felt (the module docstring), less the hand's
            self._step.wrench_into(o.wrench, o.dq, self.external_wrench)
        o.normal_force_n = float(fx * self.normal[0] + fy * self.normal[1] + fz * self.normal[2])
