"""Who may write what in a cell: the roles, and Zenoh's access control built from them.

Every service authenticates as one role (Zenoh user-password
authentication: its user name is the role) and every service applies the
same access-control list on what it receives (ingress: the subject is
the sending peer), so a message from a peer that may not write a key is
dropped at the first hop, wherever that peer connects. (Egress rules would
be checked against the *receiving* peer: a deny on robot/state for
everyone but the robot would stop the robot sending its states.) Keys not listed below are open
to any authenticated peer; unauthenticated peers cannot join at all.

======================  =========================================
key (under the prefix)  who may put it
======================  =========================================
robot/command           controller
robot/state, robot/     robot (the sim, a robot adapter, the lbr
status, sim/**,         peer's simulated side)
camera/**
robot/arm               operator
perception/**           perception
controller/status,      controller
controller/trace
controller/estop        every role (engaging is never refused)
controller/estop/       operator
release
======================  =========================================
"""

from __future__ import annotations

from typing import Any

from .keys import Keys

#: The identities of a cell. ``operator``: a person's tools (``lamps up``, e-stop release, arming).
ROLES = ("controller", "robot", "perception", "recorder", "operator")


def writers(keys: Keys) -> dict[str, tuple[str, ...]]:
    """Key expression -> the roles that may put on it (the table of the module docstring)."""
    p = keys.prefix
    return {
        keys.robot_command: ("controller",),
        keys.robot_state: ("robot",),
        keys.robot_status: ("robot",),
        f"{p}/sim/**": ("robot",),
        f"{p}/camera/**": ("robot",),
        keys.robot_arm: ("operator",),
        f"{p}/perception/**": ("perception",),
        keys.controller_status: ("controller",),
        keys.controller_trace: ("controller",),
        keys.controller_estop_release: ("operator",),
    }


def cell_acl(keys: Keys) -> dict[str, Any]:
    """Zenoh's ``access_control`` section for a cell under ``keys``: default allow, puts denied to all but writers."""
    rules, policies = [], []
    subjects = [{"id": role, "usernames": [role]} for role in ROLES]
    for i, (key, allowed) in enumerate(writers(keys).items()):
        others = [r for r in ROLES if r not in allowed]
        rule = f"put-{i}"
        rules.append({"id": rule, "permission": "deny", "flows": ["ingress"], "messages": ["put", "delete"],
                      "key_exprs": [key]})
        policies.append({"id": f"only-{'-'.join(allowed)}-{i}", "rules": [rule], "subjects": others})
    return {"enabled": True, "default_permission": "allow", "rules": rules, "subjects": subjects,
            "policies": policies}
