"""Camera frames in, stains and kappa out (arrives with issue 5)."""
