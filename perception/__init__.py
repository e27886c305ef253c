"""The perception service: camera frames in, stains and kappa out (board markers, ink per pixel, clusters)."""
