"""What the controller estimated of the arm it drives: a part of :class:`~interfaces.messages.ControllerStatus`."""

from __future__ import annotations

from typing import Annotated

import msgspec

from interfaces.message_checks import Text, check_finite

#: The longest joint vector a status carries.
MAX_JOINTS = 16
_Vec = Annotated[list[float], msgspec.Meta(max_length=MAX_JOINTS)]


class ArmEstimate(msgspec.Struct, frozen=True, array_like=True):
    """The load and the model error the controller estimated (:mod:`controller.arm_model`).

    tool_fitted : the flange load was fitted (at the first contact, from the free motion before it);
    tool_mass_kg [kg], tool_com_m (3,) [m, flange frame] : the load on the flange the controller's model does
    not carry (beyond the description's tool; with the robot compensating gravity, beyond its load data);
    tool_fit_residual_nm : the joint torque the fitted load leaves unexplained, RMS over its samples [Nm];
    correction_nm (n,) : the static torque the controller adds to its model now [Nm]; residual_nm (n,) : its
    part the fitted load does not explain (link masses, centres of mass) [Nm]; warning : ``model_mismatch: ...``
    when the correction stays at its bound (the arm differs from its model beyond what it absorbs), else "";
    tool_com_unobserved : how many directions of the load's (mass, mass x centre of mass) its samples did not
    tell (kept at the pad centre: an offset along gravity at every sample turns no joint).
    """

    tool_fitted: bool = False
    tool_mass_kg: float = 0.0
    tool_com_m: _Vec = msgspec.field(default_factory=list)
    tool_fit_residual_nm: float = 0.0
    correction_nm: _Vec = msgspec.field(default_factory=list)
    residual_nm: _Vec = msgspec.field(default_factory=list)
    warning: Text = ""
    tool_com_unobserved: Annotated[int, msgspec.Meta(ge=0, le=4)] = 0

    def __post_init__(self) -> None:
        check_finite("tool_mass_kg/tool_fit_residual_nm", (self.tool_mass_kg, self.tool_fit_residual_nm))
        check_finite("tool_com_m", self.tool_com_m)
        check_finite("correction_nm", self.correction_nm)
        check_finite("residual_nm", self.residual_nm)
