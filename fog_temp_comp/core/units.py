"""Unit conversions used across the package (REP 103: angular rates are rad/s on the wire)."""

from __future__ import annotations

import math

#: seconds per hour
S_PER_H = 3600.0
#: seconds per minute
S_PER_MIN = 60.0
#: rad/s in one deg/h
RAD_S_PER_DEG_H = math.pi / 180.0 / S_PER_H
#: deg/h in one rad/s
DEG_H_PER_RAD_S = 1.0 / RAD_S_PER_DEG_H
#: nanoseconds per second
NS_PER_S = 1_000_000_000

AXES = ('x', 'y', 'z')
