"""Who may write what in a cell: the roles, and Zenoh's access control built from them (default deny).

Every service joins as one role. By default the role is the common name of
its own TLS certificate (mutual TLS, :mod:`interfaces.credentials`: each
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
sim/**, camera/**                 lbr peer's simulated side)
<ros namespace>/** (not under     robot, bridge (zenoh-bridge-ros2dds
the prefix: ``lbr`` and           next to lbr_fri_ros2_stack and the
``camera`` by default)            camera's ROS driver)
robot/arm                         operator
perception/**                     perception
controller/status,                controller
controller/trace
controller/estop                  every role but the bridge (engaging
                                  is never refused)
controller/estop/release          operator
================================  =====================================

The recorder writes nothing the cell acts on (its identity can engage the
e-stop and read); the bridge only the ROS topics it carries.

**A router** (``lamps router``, identity ``router``, :data:`RELAY`) is not a
role: it writes nothing of its own but forwards what its clients put. On the
router the same list decides what each client may put (ingress, by the
client's certificate) and what it is sent; on a service the router's puts
are let in on every key of the cell (the router already filtered them by
their sender). Whoever holds the router's key can therefore write anything:
it belongs on the infrastructure host, like the CA.

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
#: Zenoh message kinds a role may send to and receive from another role (besides the puts of its row).
_DECLARATIONS = ["declare_subscriber", "declare_queryable", "query", "reply", "liveliness_token",
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
    return {
        keys.robot_command: ("controller",),
        keys.robot_state: ("robot",),
        keys.robot_status: ("robot",),
        f"{p}/sim/**": ("robot",),
        f"{p}/camera/**": ("robot",),
        **{f"{ns.strip('/')}/**": ("robot", "bridge") for ns in ros_namespaces},
        keys.robot_arm: ("operator",),
        f"{p}/perception/**": ("perception",),
        keys.controller_status: ("controller",),
        keys.controller_trace: ("controller",),
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


def cell_acl(keys: Keys, subject: str = "cert_common_names",
             ros_namespaces: tuple[str, ...] = DEFAULT_ROS_NAMESPACES, cell: str | None = None) -> dict[str, Any]:
    """Zenoh's ``access_control`` section for a cell under ``keys`` (default deny, see the module docstring).

    subject : how a peer's role is told: ``cert_common_names`` (mutual TLS, the default) or ``usernames``.
    cell : the robot id of a cell of a site: its roles are named ``<role>@<cell>`` (:func:`identity_name`);
    None: by the bare role.
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
        policies.append({"id": f"as-{role}", "rules": ["talk", "deliver", f"put-{role}"], "subjects": [role]})
    rules.append({"id": "relay", "permission": "allow", "flows": ["ingress"], "messages": _DATA, "key_exprs": scope})
    policies.append({"id": f"as-{RELAY}", "rules": ["talk", "deliver", "relay"], "subjects": [RELAY]})
    subjects = [{"id": role, subject: [identity_name(role, cell) if role in ROLES else role]} for role in IDENTITIES]
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
            policies.append({"id": f"as-{name}", "rules": [*talk, *own], "subjects": [name]})
    estops = [Keys.for_robot(c).controller_estop for c in cells]
    policies.append({"id": f"as-{SITE_VIEWER}", "subjects": [SITE_VIEWER],
                     "rules": [*reach(SITE_VIEWER, every), *put(SITE_VIEWER, estops)]})
    policies.append({"id": f"as-{RELAY}", "subjects": [RELAY],
                     "rules": [*reach(RELAY, every), *put(RELAY, every)]})
    names = [p["subjects"][0] for p in policies]
    return {"enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": [{"id": n, subject: [n]} for n in names], "policies": policies}
