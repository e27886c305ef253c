"""Who may write what in a cell: the roles, and Zenoh's access control built from them (default deny).

Every service joins as one role. By default the role is the common name of
its own TLS certificate (mutual TLS, :mod:`runtime.credentials`: each
service holds only its own private key, and both ends of every link prove
who they are, whichever side opened it); a cell that still uses Zenoh's
user-password authentication is named by user name instead, which identifies
only the side that *connected* (the listener's user is unknown on a link a
service opened itself, so such a link is denied everything).

Every service applies the same list on what it receives (ingress: the
subject is the sending peer) and on what it sends (egress: the subject is
the receiving peer). **Default deny**: a peer that is not one of the roles
(no certificate, another CA's, an unknown common name, a link whose remote
is unauthenticated) may do nothing; a role may put only on the keys below
and may declare subscribers, liveliness tokens and queries under the cell's
prefix (and the ROS bridge's namespace), so every role can read the whole
cell. Zenoh drops a refused message at the first hop, before the
application, and logs it (``RUST_LOG=zenoh::net::routing::interceptor::access_control=trace``).

================================  =====================================
key (under the prefix)            who may put it
================================  =====================================
robot/command                     controller
robot/state, robot/status,        robot (the sim, a robot adapter, the
robot/introduction, sim/**,       lbr peer's simulated side)
camera/**
<ros ns>/command/** (not under    robot (the lbr adapter: the commands go
the prefix: ``lbr`` and           *into* the stack; the stand-in's side
``camera`` by default)            publishes the states as robot too)
<ros ns>/state, joint_states,     robot, bridge (zenoh-bridge-ros2dds next
force_torque_broadcaster/wrench,  to lbr_fri_ros2_stack and the camera's
**/image_raw[/compressed],        ROS driver: what the stack and the camera
**/camera_info                    publish, never a command)
robot/arm                         operator
perception/**                     perception
controller/status,                controller
controller/trace,
controller/introduction
controller/estop                  every role but the bridge (engaging
                                  is never refused)
controller/estop/release          operator
================================  =====================================

The recorder writes nothing the cell acts on (its identity can engage the
e-stop and read); the bridge only the ROS topics the stack and the camera
publish: its puts are the states, never the commands (a stolen bridge
identity cannot move the arm). lbr_fri_ros2_stack ``rolling`` 218d723
publishes ``state`` (``lbr_ros2_control/src/controllers/lbr_state_broadcaster.cpp:19``),
``joint_states`` and ``force_torque_broadcaster/wrench`` (ros2_control's
broadcasters, ``lbr_ros2_control/config/lbr_controllers.yaml:8-12``) and
takes every command under ``command/`` (``lbr_torque_command_controller.cpp:27-28``
``command/torque``; ``command/joint_position``, ``command/wrench``,
``command/twist`` in the other controllers' ``on_init``).

Liveliness tokens (``alive/<service>``: start-up and compose's health
checks gate on them) are each role's own: a role may declare only the
tokens of its services (:data:`ROLE_SERVICES`), so perception's identity
cannot pretend the controller is up.

**A router** (``lamps router``, identity ``router``, :data:`RELAY`) is not a
role: it writes nothing of its own but forwards what its clients put. On the
router the same list decides what each client may put (ingress, by the
client's certificate) and what it is sent. The router relays, it does not
vouch: a service accepts the router's identity only when it is the
router's *client* (``mode = "client"``: its one link is the router it
connected to and checked); a service in peer mode has no policy for it, so
the router's key used as a peer gets nothing. And what moves the arm is
checked end to end behind the router (:mod:`interfaces.arm_auth`): the
robot side applies only commands authenticated by a session the
controller's own key signed, and an e-stop release or an arming only when
signed by the operator's key, whoever relayed them. The router's key is
kept with the CA, never in a service's folder.

**Several cells through one router** (a *site*, :func:`site_acl`): each
cell has its own robot id and its own identities, whose common names carry
the cell, ``<role>@<robot_id>`` (``controller@iiwa-1``; ``lamps credentials
DIR --cells ID,...``). On the router, a cell's role puts only its row above
under its own prefix ``lamps/<robot_id>/`` and declares, reads and is sent
nothing of another cell's: cell A's controller cannot command cell B's
robot, nor A's operator release B's e-stop. One more identity,
``site-viewer`` (:data:`SITE_VIEWER`: one recorder or live view for every
cell), reads every cell and puts only an engaging e-stop on any of them. A
cell's services check the same names on their own side
(:func:`cell_acl` with ``cell``), so a peer link between two cells' services
carries no more than the router would. The ROS namespaces are the cell's own
business (its bridge links to its robot side, not to the router): the site
list gives no role a key outside the cells' prefixes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from .errors import ConfigError
from .keys import Keys

#: The identities of a cell. ``operator``: a person's tools (``lamps up``, e-stop release, arming); ``bridge``:
#: zenoh-bridge-ros2dds on the robot's PC.
ROLES = ("controller", "robot", "perception", "recorder", "operator", "bridge")
#: The ROS namespaces the bridge carries: lbr_fri_ros2_stack's default robot_name and a camera driver's default.
DEFAULT_ROS_NAMESPACES = ("lbr", "camera")
#: The identity of a Zenoh router (``lamps router``): relays the roles' puts, checked at the router.
RELAY = "router"
#: Every identity ``lamps credentials`` makes: the roles and the router.
IDENTITIES = (*ROLES, RELAY)
#: A site's reader of every cell (one recorder or live view through the router): reads all, engages any e-stop.
SITE_VIEWER = "site-viewer"
#: Between the role and the cell in a common name: ``controller@iiwa-1`` (never in a robot id).
CELL_MARK = "@"
#: The services (``alive/<service>`` liveliness tokens) each role runs; a role declares only its own tokens.
ROLE_SERVICES: dict[str, tuple[str, ...]] = {
    "controller": ("controller",),
    "robot": ("robot", "sim", "lbr-peer", "camera"),
    "perception": ("perception",),
    "recorder": ("recorder", "foxglove"),
    "operator": ("launcher", "teach", "operator"),
    "bridge": (),
}
#: The topics (relative to a ROS namespace) zenoh-bridge-ros2dds carries *out of* the stack and the camera:
#: the bridge's puts. lbr_fri_ros2_stack publishes ``state``, ``joint_states`` and the wrench broadcaster's
#: ``force_torque_broadcaster/wrench``; a camera driver ``<camera>/image_raw[/compressed]``, ``camera_info``.
ROS_PUBLISHED = ("state", "joint_states", "force_torque_broadcaster/wrench", "**/image_raw", "**/image_raw/compressed",
                 "**/camera_info")
#: Zenoh message kinds a role may send to and receive from another role (besides the puts of its row).
_DECLARATIONS = ["declare_subscriber", "declare_queryable", "query", "reply",
                 "declare_liveliness_subscriber", "liveliness_query"]
_DATA = ["put", "delete"]


def identity_name(role: str, cell: str | None = None) -> str:
    """The common name of ``role``'s certificate: the role (a cell of its own), ``<role>@<cell>`` in a site."""
    return role if cell is None else f"{role}{CELL_MARK}{cell}"


def role_and_cell(name: str) -> tuple[str, str | None]:
    """(role, robot id or None) of a certificate's common name (:func:`identity_name` inverted)."""
    role, mark, cell = name.partition(CELL_MARK)
    return (role, cell) if mark else (name, None)


def check_cells(cells: Sequence[str]) -> tuple[str, ...]:
    """The robot ids of a site, checked: robot ids (:meth:`Keys.for_robot`), distinct, none named like an
    identity folder of ``lamps credentials`` (``ca``, ``router``, ``site-viewer``, a role)."""
    cells = tuple(cells)
    for c in cells:
        Keys.for_robot(c)
        if c in ("ca", *IDENTITIES, SITE_VIEWER):
            raise ConfigError(f"robot id {c!r} is the name of a credentials folder; choose another")
    if len(set(cells)) != len(cells):
        raise ConfigError(f"robot ids must be distinct, got {list(cells)}")
    return cells


def writers(keys: Keys, ros_namespaces: tuple[str, ...] = DEFAULT_ROS_NAMESPACES) -> dict[str, tuple[str, ...]]:
    """Key expression -> the roles that may put on it (the table of the module docstring)."""
    p = keys.prefix
    ros = [ns.strip("/") for ns in ros_namespaces]
    return {
        keys.robot_command: ("controller",),
        keys.robot_state: ("robot",),
        keys.robot_status: ("robot",),
        keys.robot_introduction: ("robot",),
        f"{p}/sim/**": ("robot",),
        f"{p}/camera/**": ("robot",),
        **{f"{ns}/command/**": ("robot",) for ns in ros},
        **{f"{ns}/{topic}": ("robot", "bridge") for ns in ros for topic in ROS_PUBLISHED},
        keys.robot_arm: ("operator",),
        f"{p}/perception/**": ("perception",),
        keys.controller_status: ("controller",),
        keys.controller_trace: ("controller",),
        keys.controller_introduction: ("controller",),
        keys.controller_estop: tuple(r for r in ROLES if r != "bridge"),
        keys.controller_estop_release: ("operator",),
    }


def may_put(keys: Keys, role: str, key: str, ros_namespaces: tuple[str, ...] = DEFAULT_ROS_NAMESPACES) -> bool:
    """Whether ``role`` may put on the concrete key ``key`` (what the access list lets through)."""
    import zenoh

    k = zenoh.KeyExpr(key)
    return any(role in allowed and zenoh.KeyExpr(expr).intersects(k)
               for expr, allowed in writers(keys, ros_namespaces).items())


def _check_subject(subject: str) -> None:
    if subject not in ("cert_common_names", "usernames"):
        raise ValueError(f"subject must be cert_common_names or usernames, got {subject!r}")


def _token_rules(name: str, keys: Keys, role: str | None) -> tuple[list[dict[str, Any]], list[str]]:
    """(rules, their ids) for liveliness tokens: everyone's are delivered (egress) under the cell's prefix; a role
    declares (ingress) only its services' ``alive/<service>`` (:data:`ROLE_SERVICES`); ``role`` None: every token
    (a relay)."""
    rules: list[dict[str, Any]] = [{"id": f"tokens-out-{name}", "permission": "allow", "flows": ["egress"],
                                    "messages": ["liveliness_token"], "key_exprs": [f"{keys.prefix}/**"]}]
    own = [f"{keys.prefix}/**"] if role is None else [keys.alive(s) for s in ROLE_SERVICES[role]]
    if own:  # Zenoh refuses a rule without keys
        rules.append({"id": f"tokens-in-{name}", "permission": "allow", "flows": ["ingress"],
                      "messages": ["liveliness_token"], "key_exprs": own})
    return rules, [r["id"] for r in rules]


def cell_acl(keys: Keys, subject: str = "cert_common_names",
             ros_namespaces: tuple[str, ...] = DEFAULT_ROS_NAMESPACES, cell: str | None = None,
             relay: bool = False) -> dict[str, Any]:
    """Zenoh's ``access_control`` section for a cell under ``keys`` (default deny, see the module docstring).

    subject : how a peer's role is told: ``cert_common_names`` (mutual TLS, the default) or ``usernames``.
    cell : the robot id of a cell of a site: its roles are named ``<role>@<cell>`` (:func:`identity_name`);
    None: by the bare role.
    relay : accept the router's identity (:data:`RELAY`) and the puts it relays: only for a router's client (its
    one link is the router it connected to) or a router; a peer never accepts it.
    """
    _check_subject(subject)
    scope = [f"{keys.prefix}/**", *(f"{ns.strip('/')}/**" for ns in ros_namespaces)]
    rules: list[dict[str, Any]] = [
        {"id": "talk", "permission": "allow", "flows": ["egress", "ingress"], "messages": _DECLARATIONS,
         "key_exprs": scope},
        {"id": "deliver", "permission": "allow", "flows": ["egress"], "messages": _DATA, "key_exprs": scope},
    ]
    policies = []
    for role in ROLES:
        exprs = [k for k, allowed in writers(keys, ros_namespaces).items() if role in allowed]
        rules.append({"id": f"put-{role}", "permission": "allow", "flows": ["ingress"], "messages": _DATA,
                      "key_exprs": exprs})
        tokens, token_ids = _token_rules(role, keys, role)
        rules += tokens
        policies.append({"id": f"as-{role}", "rules": ["talk", "deliver", f"put-{role}", *token_ids],
                         "subjects": [role]})
    names = list(ROLES)
    if relay:
        rules.append({"id": "relay", "permission": "allow", "flows": ["ingress"], "messages": _DATA,
                      "key_exprs": scope})
        tokens, token_ids = _token_rules(RELAY, keys, None)
        rules += tokens
        policies.append({"id": f"as-{RELAY}", "rules": ["talk", "deliver", "relay", *token_ids],
                         "subjects": [RELAY]})
        names.append(RELAY)
    subjects = [{"id": n, subject: [identity_name(n, cell) if n in ROLES else n]} for n in names]
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}


def site_acl(cells: Sequence[str], subject: str = "cert_common_names") -> dict[str, Any]:
    """Zenoh's ``access_control`` section for the router (or the site viewer) of several cells, ``cells`` their
    robot ids: each cell's roles (``<role>@<robot_id>``) put their row under their own prefix and talk and read
    only there; :data:`SITE_VIEWER` reads every cell and engages any e-stop; a router relays (module docstring)."""
    _check_subject(subject)
    cells = check_cells(cells)
    if not cells:
        raise ConfigError("a site's access list needs the robot id of at least one cell")
    every = [f"{Keys.for_robot(c).prefix}/**" for c in cells]
    rules: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []

    def reach(name: str, scope: list[str]) -> list[str]:  # declarations both ways, data sent: within scope
        rules.append({"id": f"talk-{name}", "permission": "allow", "flows": ["egress", "ingress"],
                      "messages": _DECLARATIONS, "key_exprs": scope})
        rules.append({"id": f"deliver-{name}", "permission": "allow", "flows": ["egress"], "messages": _DATA,
                      "key_exprs": scope})
        return [f"talk-{name}", f"deliver-{name}"]

    def tokens(name: str, keys: Keys, role: str | None) -> list[str]:
        made, ids = _token_rules(name, keys, role)
        rules.extend(made)
        return ids

    def put(name: str, exprs: list[str]) -> list[str]:
        if not exprs:  # Zenoh refuses a rule without keys; nothing to put is the default anyway
            return []
        rules.append({"id": f"put-{name}", "permission": "allow", "flows": ["ingress"], "messages": _DATA,
                      "key_exprs": exprs})
        return [f"put-{name}"]

    for c in cells:
        keys = Keys.for_robot(c)
        talk = reach(c, [f"{keys.prefix}/**"])
        rows = writers(keys, ())
        for role in ROLES:
            name = identity_name(role, c)
            own = put(name, [k for k, allowed in rows.items() if role in allowed])
            policies.append({"id": f"as-{name}", "rules": [*talk, *own, *tokens(name, keys, role)],
                             "subjects": [name]})
    estops = [Keys.for_robot(c).controller_estop for c in cells]
    viewer_tokens = [i for c in cells for i in tokens(f"{SITE_VIEWER}-{c}", Keys.for_robot(c), "recorder")]
    relay_tokens = [i for c in cells for i in tokens(f"{RELAY}-{c}", Keys.for_robot(c), None)]
    policies.append({"id": f"as-{SITE_VIEWER}", "subjects": [SITE_VIEWER],
                     "rules": [*reach(SITE_VIEWER, every), *put(SITE_VIEWER, estops), *viewer_tokens]})
    policies.append({"id": f"as-{RELAY}", "subjects": [RELAY],
                     "rules": [*reach(RELAY, every), *put(RELAY, every), *relay_tokens]})
    names = [p["subjects"][0] for p in policies]
    return {"enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": [{"id": n, subject: [n]} for n in names], "policies": policies}
