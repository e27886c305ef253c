"""No silent insecurity: whether a service may start with the security its settings give it, and what it says.

A service of the cell (sim, robot side, controller, perception, recorder,
live view, router, teach) starts only

* with an identity (mutual TLS, ``[zenoh] identity``) and the cell's access
  list, which an identity brings unless turned off; or
* without either, or with the access list off, when told so on purpose:
  ``--insecure`` / ``[zenoh] insecure = true`` / ``LAMPS_ZENOH_INSECURE=true``.
  It then logs a warning and every status it publishes says ``INSECURE``
  (:func:`security_summary`, carried by :class:`~runtime.session.ServiceNode`).

Whatever the flag, the robot role's access list cannot be turned off (its
identity moves the arm).

Everything else refused names the problem and the way out (:class:`ConfigError`).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from interfaces.access import role_and_cell
from interfaces.errors import ConfigError

if TYPE_CHECKING:  # runtime.config calls check_service_security
    from .config import ZenohSettings

#: What a status says of a service on the in-process bus (no network, nothing to authenticate).
IN_PROCESS = "in-process (no network)"


def role_of(settings: ZenohSettings) -> str | None:
    """The role ``settings`` join as: their certificate's common name (``controller@iiwa-1`` -> ``controller``), or
    the user-password user; None without an identity; "" when its certificate cannot be read here (a configuration
    checked away from its host: opening the session names the file)."""
    if settings.tls_ca:
        from .certificates import common_name

        try:
            return role_and_cell(common_name(Path(settings.tls_certificate)))[0]
        except ConfigError:
            return ""
    return settings.user or None


def security_summary(settings: ZenohSettings) -> str:
    """One line for every status: ``mtls+acl as <role>``, or ``INSECURE: ...`` naming what is missing."""
    role = role_of(settings)
    if role is None:
        return "INSECURE: no identity, plain links, no access list"
    link = "mtls" if settings.tls_ca else "usrpwd"
    if not settings.access_control:
        return f"INSECURE: {link} as {role or '?'}, access list off"
    return f"{link}+acl as {role or '?'}"


def check_service_security(settings: ZenohSettings) -> str:
    """The summary (:func:`security_summary`) of settings a service may start with; ConfigError otherwise."""
    role = role_of(settings)
    if role == "robot" and not settings.access_control:
        raise ConfigError("[zenoh] access_control cannot be turned off for the robot role: its identity moves the "
                          "arm (unset LAMPS_ZENOH_ACCESS_CONTROL / LAMPS_ACCESS_CONTROL; --insecure does not "
                          "change this)")
    if role is None and not settings.insecure:
        raise ConfigError("no identity: this service would run plain links with no access list. Give it its "
                          "role's folder (LAMPS_ZENOH_IDENTITY, made by 'lamps credentials DIR'), or run it "
                          "with --insecure (LAMPS_ZENOH_INSECURE=true) on purpose, on a machine of your own")
    if role is not None and not settings.access_control and not settings.insecure:
        raise ConfigError(f"[zenoh] access_control is off for the {role or 'given'} role: every peer of the cell "
                          "could put anything here. Remove the setting (an identity brings its access list), or run "
                          "with --insecure on purpose")
    return security_summary(settings)  # the node warns when it opens (after the rest of the configuration)
