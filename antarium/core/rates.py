"""The dome's frame rate: the one number every stage and benchmark is measured against."""

DOME_RATE_HZ = 190.0  # frames per second the panels show (Kócsi et al. 2020)
FRAME_PERIOD_S = 1.0 / DOME_RATE_HZ  # 5.26 ms
