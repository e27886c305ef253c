"""Learning a LAMPS skill from a demonstration (offline; never imported by :mod:`lampskit.core`).

- :mod:`.demo`, :mod:`.demo_io`: demonstrations and their readers (CSV, NPZ, QTM TSV, MATLAB);
  :mod:`.synth`: synthetic wiping demonstrations with true labels; :mod:`.derivatives`.
- Segmentation (Procedure 1): :mod:`.segmentation` (the method and its result),
  :mod:`.optics`, :mod:`.reachability` (steps 1-4), :mod:`.time_runs` (steps 5-7),
  :mod:`.cluster_baselines` (K-Means, Affinity Propagation), :mod:`.segmentation_scores`.
- Fitting: :mod:`.periodic_phase` (frequency, phase), :mod:`.gmr` (GMM-GMR template),
  :mod:`.periodic_fit`, :mod:`.transitional_fit`, :mod:`.baselines` (Fig. 6's).
- :mod:`.learn`: a whole skill from one demonstration.
"""

__all__ = [
    "bag_maths", "bags", "baselines", "cluster_baselines", "contact", "cut_margins", "demo", "demo_io", "derivatives",
    "fusion", "gmr", "learn", "lifts", "optics", "periodic_fit", "periodic_phase", "phase_continuity", "reachability",
    "segment_plot", "segmentation", "segmentation_scores", "segments_file", "synth", "synth_human", "synth_messy",
    "synth_pieces", "takes", "time_runs", "transitional_fit"
]
