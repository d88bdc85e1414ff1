# Rasteriser support: PNG output, metrics (Hausdorff via FLANN).
