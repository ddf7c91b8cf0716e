"""Better than the metadata: what the telemetry gets wrong, estimated from the images themselves.

:mod:`.tiepoints` finds the same ground in several frames (SIFT, matched only between frames the
poses predict overlap, verified by RANSAC, joined into tracks); :mod:`.adjust` solves for the
installation, heading bias and time offset together with every tie point's ground position, the
DEM as a soft constraint (Levenberg-Marquardt on the Schur complement), and says what the
geometry could not separate.
"""
