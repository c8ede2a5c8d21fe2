"""The hybrid solver (IFENN), on the pixel grid of :mod:`ifenn.pixels`: the pixel phase-field
step (``pixel_step``), process-zone inference (``process_zone``), the verified step
(``verification``) and the hybrid runs (``runs``).
"""
