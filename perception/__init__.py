"""The perception service: camera frames in, stains and kappa out (board markers, ink per pixel, clusters)."""

__all__ = [
    "arm_mask", "board", "calibration", "check_board", "classify", "cli", "cluster", "debug", "evaluate", "fit_inks",
    "frames", "ink_areas", "kappa", "live_capture", "occlusion", "params", "photo_score", "pipeline", "rectify",
    "ros_images", "self_filter", "service", "smear", "sources", "track_kernels", "tracking", "unmix"
]
