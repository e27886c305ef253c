"""The control law: Cartesian impedance with Pinocchio, contact-force regulation and limits.

Pure maths on numpy arrays and a Pinocchio model; no network, no simulator.
The controller service (:mod:`controller.service`) runs it in its fixed-rate loop.
"""

__all__ = [
    "demand_kernels", "force", "impedance", "kernels", "limit_kernels", "limits", "model_correction", "params",
    "records", "watch",
]
