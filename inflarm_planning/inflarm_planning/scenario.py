"""The paper's planning scenario (section 4.3.1 of 001_b59ad71c956a1751) and the alert margin rule.

The paper gives the scenario in millimetres; it is converted here, once, to metres.
"""

from inflarm_planning.collision import Cuboid

MM = 1e-3

START = (0.0 * MM, 130.0 * MM, 710.0 * MM)
"""Start of the end, (0, 130, 710) mm in ``sra_mount`` [m]."""

GOAL = (130.0 * MM, 0.0 * MM, 730.0 * MM)
"""Goal of the end, (130, 0, 730) mm [m]."""

OBSTACLE = Cuboid((35.0 * MM, 40.0 * MM, 650.0 * MM), (140.0 * MM, 140.0 * MM, 780.0 * MM),
                  'paper obstacle')
"""The cuboid of Fig 10: x 35-140, y 40-140, z 650-780 mm [m]."""

ACTUATOR_WIDTH = 50.0 * MM
"""Width of the PEAs we assume [m]. The paper gives none; its rule (alert margin larger than half
the width) must leave its own start point free, which lies 35 mm from the obstacle, so the width
is below 70 mm; and the path of Fig 11 turns with x and y both close to 0, i.e. around an alert
region reaching almost to the arm's axis, which needs a margin near 30-35 mm."""

TRACKING_ERROR = 5.0 * MM
"""Largest tracking error of the planned path in the experiment, 'smaller than 5 mm' [m]."""

ALERT_MARGIN = 0.030
"""The paper's rule with our width: half the width plus the tracking error, 30 mm [m]."""
